"""Where presets are found: the shipped presets' names and files, and a NAME_OR_FILE resolved.

Light (no numpy): the command line checks a preset's name before the colour
library loads. :mod:`wbcgrade.color.presets` re-exports these.
"""

from __future__ import annotations

import os
from pathlib import Path

from wbcgrade.errors import InputError

__all__ = ["shipped_presets_dir", "list_presets", "RETIRED_PRESETS", "resolve_preset"]


def shipped_presets_dir() -> Path:
    """Folder of the presets installed with the package."""
    return Path(__file__).resolve().parents[1] / "presets_data"


def list_presets() -> list[tuple[str, Path]]:
    """(name, path) of every shipped preset, sorted by name."""
    folder = shipped_presets_dir()
    if not folder.is_dir():
        return []
    return sorted((p.stem, p) for p in folder.glob("*.npz"))


#: Presets shipped before the presets became looks: name -> what to use instead.
RETIRED_PRESETS = {
    "landscape": "the palettes of the sample landscapes",
    "mixed": "the palettes of the sample photos",
}


def resolve_preset(name_or_path: str) -> Path:
    """A preset file from a shipped preset's NAME or a FILE path.

    An existing path wins; otherwise the name is looked up among the shipped
    presets. Raises InputError listing the available names (and saying so
    when the name is one of :data:`RETIRED_PRESETS`).
    """
    candidate = Path(name_or_path).expanduser()
    if candidate.is_file():
        return candidate
    shipped = dict(list_presets())
    if name_or_path in shipped:
        return shipped[name_or_path]
    folded = {name.casefold(): path for name, path in shipped.items()}
    if name_or_path.casefold() in folded:  # "Warm": names are lower case
        return folded[name_or_path.casefold()]
    if candidate.suffix or os.sep in name_or_path:
        raise InputError(f"{name_or_path}: no such preset file")
    names = ", ".join(shipped) or "none installed"
    if name_or_path in RETIRED_PRESETS:
        raise InputError(
            f"preset {name_or_path!r} ({RETIRED_PRESETS[name_or_path]}) is no longer shipped: "
            f"the shipped presets are looks ({names}); for palettes of your own photos "
            "use {style_dir} DIR or `wbcgrade preset build DIR -o FILE.npz`",
            fields=("style_dir",))
    raise InputError(f"unknown preset {name_or_path!r} (shipped presets: {names})")
