"""Every style source the page can switch to, the save folder, and the photo they share.

The page opens on one style source (``--style DIR`` or the first ``--preset``)
and lists others in its preset picker: the presets given on the command
line, then every shipped preset. Each source is a
:class:`wbcgrade.explore.server.Studio` (its styles, its look grade, its
palette fit and job worker), loaded the first time the page picks it; the
photo is read once for all of them. Saved photos go into one folder, fixed
when the server starts.
"""

from __future__ import annotations

import os
import threading
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from wbcgrade.color.outcome import change_words
from wbcgrade.explore.engine import blend_looks, grade_file_of, load_session, shipped_presets
from wbcgrade.explore.server import Studio
from wbcgrade.explore.settings import RequestError

__all__ = ["Explorer", "StyleChoice", "style_choices"]


@dataclass(frozen=True)
class StyleChoice:
    """One entry of the preset picker: a style folder or a preset (name or file)."""

    label: str
    style_dir: str | None = None
    preset: str | None = None

    def as_json(self) -> dict:
        return {"label": self.label, "kind": "folder" if self.style_dir else "preset"}


def style_choices(style_dir: str | None, presets: list[str]) -> list[StyleChoice]:
    """The picker's entries: the folder (when given), the presets given, the shipped ones
    not given by name. The first is where the page opens."""
    out = []
    if style_dir is not None:
        out.append(StyleChoice(f"style folder {Path(style_dir).name or style_dir}",
                               style_dir=str(style_dir)))
    for preset in presets:
        label = Path(preset).name if Path(preset).suffix == ".npz" else preset
        out.append(StyleChoice(f"preset {label}", preset=preset))
    given = set(presets)
    for name in shipped_presets():
        if name not in given:
            out.append(StyleChoice(f"preset {name}", preset=name))
    return out


class Explorer:
    """What the server serves: the photo, the style sources, the save folder.

    Parameters
    ----------
    first : the :class:`~wbcgrade.explore.server.Studio` of ``choices[0]`` (loaded).
    choices : the preset picker's entries (:func:`style_choices`).
    save_dir : the folder saved photos go to (exists; fixed for the server's life).

    Attributes the page's palette routes used before there were several sources
    (``session``, ``fit``, ``fitted``, ``worker``, ``preview``, ...) are the first
    source's.
    """

    def __init__(self, first, choices: list[StyleChoice], save_dir: str | os.PathLike) -> None:
        self.choices = choices
        self.save_dir = Path(save_dir)
        self._studios = {0: first}
        self._lock = threading.Lock()
        self._loading = {index: threading.Lock() for index in range(len(choices))}
        self._save_lock = threading.Lock()
        self._stop = threading.Event()
        self._prefetch: threading.Thread | None = None

    def __getattr__(self, name: str):
        if name.startswith("_"):
            raise AttributeError(name)
        return getattr(self._studios[0], name)

    def source(self, index) -> object:
        """The Studio of picker entry ``index`` (loaded on first use; RequestError when
        there is no such entry)."""
        if isinstance(index, bool) or not isinstance(index, int) \
                or not 0 <= index < len(self.choices):
            raise RequestError(f"source must be a number from 0 to {len(self.choices) - 1}")
        studio = self._studios.get(index)
        if studio is not None:
            return studio
        with self._loading[index]:  # one load per source; the others go on meanwhile
            studio = self._studios.get(index)
            if studio is None:
                first = self._studios[0].session
                choice = self.choices[index]
                session = load_session(first.photo, choice.style_dir, choice.preset,
                                       loaded=first.loaded, setting_names=first.setting_names)
                studio = Studio(session)
                with self._lock:
                    self._studios[index] = studio
            return studio

    def prefetch(self) -> threading.Thread:
        """Load every other source and its look grade in a background thread at lower
        priority, so that picking one shows its grade at once; -> the thread."""
        def run() -> None:
            try:
                os.setpriority(os.PRIO_PROCESS, threading.get_native_id(), 10)
            except (AttributeError, OSError):  # pragma: no cover - not Linux
                pass
            for index in range(1, len(self.choices)):
                if self._stop.is_set():
                    return
                try:
                    self.source(index).session.look_grade()
                except Exception:  # noqa: BLE001 - the page reports it when picked
                    continue

        thread = threading.Thread(target=run, daemon=True, name="explore-sources")
        thread.start()
        self._prefetch = thread
        return thread

    def state(self, index: int = 0, palette: bool = False) -> dict:
        """The page's data for source ``index``: the photo, the picker, the look grade (what
        ``apply`` gives) and, with ``palette``, the palette fit (fitted now if needed)."""
        studio = self.source(index)
        session = studio.session
        _, look = studio.look(1.0)
        height, width = session.preview.shape[:2]
        out = {"photo": session.photo, "names": session.names,
               "styles": self.choices[index].label, "source": index,
               "sources": [c.as_json() for c in self.choices],
               "look": {"grade": look["grade"], "command": look["command"]},
               "save_dir": str(self.save_dir), "lut_size": session.lut_size,
               "preview": {"width": width, "height": height},
               "formats": studio.formats, "sizes": studio.sizes}
        if palette:  # the page's palette mode starts: its job worker too; the other
            with self._lock:  # sources' workers stop (started again when picked again)
                others = [s for i, s in self._studios.items() if i != index]
            for other in others:
                other.close()
            studio.worker  # noqa: B018 - started on first use
            out.update({k: v for k, v in studio.state().items()
                        if k in ("fit", "fitted", "fitted_text", "command_prefix")})
        return out

    def blended(self, index: int, strength: float, blend: tuple[int, float]):
        """The look of entry ``index`` blended with entry ``blend[0]``'s (its share
        ``blend[1]``) at ``strength`` -> (Grade, the map at blend 1, what it is as the page's
        outcome dict)."""
        other, amount = blend
        first, second = self.source(index), self.source(other)
        names = (self.choices[index].label, self.choices[other].label)
        session = first.session
        grade, mixed, change = blend_looks(
            session.look_grade(), second.session.look_grade(), amount, strength, names,
            session.hists[session.base.fit.bins])
        words = (f"a blend of two looks: {100 * (1 - amount):.0f} % {names[0]} and "
                 f"{100 * amount:.0f} % {names[1]} (each the grade apply gives), strength "
                 f"{strength:.2f}; this photo's colours move {change_words(change)}")
        return grade, mixed, {"source": "blend", "strength": strength, "blend": strength,
                              "look_strength": None, "mean_change_255": round(change, 3),
                              "words": words, "blend_of": list(names), "amount": amount}

    def look(self, index: int, strength: float, blend: tuple[int, float] | None = None):
        """The look the page shows -> (its 33^3 map at blend 1, meta): entry ``index``'s
        (the grade ``apply`` gives), or a blend of two (no ``apply`` command: the grade
        file a save writes, or the exported LUT, reproduces it)."""
        if blend is None:
            return self.source(index).look(strength)
        _, mixed, outcome = self.blended(index, strength, blend)
        return np.ascontiguousarray(mixed, dtype=np.float32), {
            "kind": "exact", "mode": "look", "strength": strength, "grade": outcome,
            "command": None}

    def export_look(self, index: int, strength: float, blend: tuple[int, float] | None,
                    lut_format: str, size: int) -> tuple[str, bytes]:
        """The LUT file of the look the page shows."""
        studio = self.source(index)
        if blend is None:
            return studio.export_mode("look", None, strength, lut_format, size)
        if lut_format not in studio.formats or size not in studio.sizes:
            return studio.export_mode("look", None, strength, lut_format, size)  # refused
        grade, _, outcome = self.blended(index, strength, blend)
        return studio.session.export_grade(grade, lut_format, size, outcome["words"],
                                           "wbcgrade apply PHOTO --look THIS_FILE --no-regrain")

    def save(self, index: int, mode: str, settings, strength: float,
             blend: tuple[int, float] | None = None) -> dict:
        """Grade the full-size photo as the page shows it and save it into the save folder
        (a blend with its grade file beside it, which the command applies)."""
        import shlex


        studio = self.source(index)
        if mode == "look" and blend is not None:
            grade, _, outcome = self.blended(index, strength, blend)
            with self._save_lock:
                path = studio.session.save(grade, self.save_dir, with_grade=True)
            command = " ".join(shlex.quote(p) for p in (
                "wbcgrade", "apply", studio.session.photo, "--look", str(grade_file_of(path)),
                "--no-regrain"))
            return {"file": path.name, "path": str(path), "folder": str(self.save_dir),
                    "command": command, "grade": outcome["words"],
                    "grade_file": grade_file_of(path).name}
        grade, words, command = studio.grade_of(mode, settings, strength)
        with self._save_lock:
            path = studio.session.save(grade, self.save_dir)
        return {"file": path.name, "path": str(path), "folder": str(self.save_dir),
                "command": command, "grade": words}

    def close(self) -> None:
        """Stop the prefetch (after the source it is loading) and every source's job worker
        (a thread left in the colour library's native code aborts the interpreter's exit)."""
        self._stop.set()
        if self._prefetch is not None:
            self._prefetch.join(60)
        with self._lock:
            studios = list(self._studios.values())
        for studio in studios:
            studio.close()
