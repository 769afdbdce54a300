"""The settings a batch's outputs depend on, recorded in its output folder.

A rerun with other settings (styles, options, series mode) is told which
changed, so that it does not mix grades made two ways in one folder.
"""

from __future__ import annotations

import json
import os
from collections.abc import Sequence
from pathlib import Path

from wbcgrade._publish import atomic_path
from wbcgrade.color.options import GradeOptions

__all__ = ["SETTINGS_FILE", "batch_settings", "settings_changed", "write_settings"]

#: File in the output folder recording the settings of the last batch run there.
SETTINGS_FILE = ".wbcgrade-batch.json"


def batch_settings(source: str, names: Sequence[str], options: GradeOptions,
                   consistent: bool) -> dict:
    """What determines the outputs of a batch (JSON-friendly; the options by their flat
    names, as earlier runs recorded them); ``source`` and ``names``: the style set's
    folder or preset and its style names, or a saved grade's file and names."""
    return {"styles": source, "style_names": list(names),
            "options": options.flat(), "consistent": bool(consistent)}


def settings_changed(out_dir: str | os.PathLike, settings: dict) -> list[str]:
    """Names of the settings that differ from those recorded in ``out_dir`` (none if unrecorded)."""
    try:
        previous = json.loads((Path(out_dir) / SETTINGS_FILE).read_text("utf-8"))
    except (OSError, ValueError, RecursionError):  # (RecursionError: nested too deep)
        return []
    if not isinstance(previous, dict):
        return []
    changed = [k for k in ("styles", "style_names", "consistent")
               if previous.get(k) != settings[k]]
    old = previous.get("options") if isinstance(previous.get("options"), dict) else {}
    changed += [k for k, v in settings["options"].items() if old.get(k) != v]
    return changed


def write_settings(out_dir: str | os.PathLike, settings: dict) -> None:
    """Record the settings of this run in ``out_dir`` (atomically; the batch's own
    record, replaced by every run that writes into the folder)."""
    path = Path(out_dir) / SETTINGS_FILE
    with atomic_path(path, overwrite=True) as tmp, open(tmp, "w", encoding="utf-8") as handle:
        json.dump(settings, handle, indent=1)
