"""Colour grading domain: photos <-> RGB histograms, colour maps, LUTs and presets.

The front door: the names below, loaded on first use (PEP 562), so that
``import wbcgrade.color`` imports no numerics.

>>> import wbcgrade.color as wc
>>> styles = wc.load_preset("warm")                  # a shipped preset's name, or a file
>>> rgb = wc.read_image("samples/chelsea.jpg").rgb()  # doctest: +SKIP
>>> graded, grade = wc.grade_array(rgb, styles)       # doctest: +SKIP

- grade: :func:`grade_array` (arrays in, arrays out: styles, or a saved
  :class:`Grade` applied as it is), :func:`apply_photo` (a photo file graded
  and written, with its LUT and saved grade);
- the styles and grades: :func:`load_preset` (a shipped preset's name or a
  preset file), :func:`load_style_folder` (a folder of style photos),
  :func:`load_grade` / :func:`save_grade` (a saved grade: JSON, ``.cube``, ``.clf``);
- files: :func:`read_image`, :func:`write_image`, :func:`write_lut`;
- types: :class:`GradeOptions`, :class:`Grade`, :class:`GradeOutcome`,
  :class:`StyleSet`, :class:`Image`.
"""

from __future__ import annotations

import importlib

#: Front-door name -> (module under ``wbcgrade.color``, its name there).
_FRONT_DOOR = {
    "grade_array": ("grading", "grade_array"),
    "apply_photo": ("workflow", "apply_photo"),
    "load_preset": ("presets", "load_preset"),
    "load_style_folder": ("presets", "load_style_folder"),
    "load_grade": ("saved_grade", "load_look"),
    "save_grade": ("saved_grade", "save_grade"),
    "read_image": ("imageio", "read_image"),
    "write_image": ("imageio", "write_image"),
    "write_lut": ("lut", "write_grade_lut"),
    "GradeOptions": ("options", "GradeOptions"),
    "Grade": ("grading", "Grade"),
    "GradeOutcome": ("outcome", "GradeOutcome"),
    "StyleSet": ("presets", "StyleSet"),
    "Image": ("imageio", "Image"),
}

__all__ = list(_FRONT_DOOR)


def __getattr__(name: str):
    """Load a front-door name on first use (``wbcgrade.color.grade_array``)."""
    try:
        module, attribute = _FRONT_DOOR[name]
    except KeyError:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}") from None
    value = getattr(importlib.import_module(f"{__name__}.{module}"), attribute)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
