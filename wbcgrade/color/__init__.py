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

#: Front-door name -> (module, its name there).
_FRONT_DOOR = {
    "grade_array": ("wbcgrade.color.grade.grading", "grade_array"),
    "apply_photo": ("wbcgrade.photos.workflow", "apply_photo"),
    "load_preset": ("wbcgrade.color.presets", "load_preset"),
    "load_style_folder": ("wbcgrade.color.presets", "load_style_folder"),
    "load_grade": ("wbcgrade.color.grade.saved_grade", "load_look"),
    "save_grade": ("wbcgrade.color.grade.saved_grade", "save_grade"),
    "read_image": ("wbcgrade.color.io.images", "read_image"),
    "write_image": ("wbcgrade.color.io.images", "write_image"),
    "write_lut": ("wbcgrade.color.mapping.lut", "write_grade_lut"),
    "GradeOptions": ("wbcgrade.color.options", "GradeOptions"),
    "Grade": ("wbcgrade.color.grade.grading", "Grade"),
    "GradeOutcome": ("wbcgrade.color.outcome", "GradeOutcome"),
    "StyleSet": ("wbcgrade.color.presets", "StyleSet"),
    "Image": ("wbcgrade.color.io.images", "Image"),
}

__all__ = list(_FRONT_DOOR)


def __getattr__(name: str):
    """Load a front-door name on first use (``wbcgrade.color.grade_array``)."""
    try:
        module, attribute = _FRONT_DOOR[name]
    except KeyError:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}") from None
    value = getattr(importlib.import_module(module), attribute)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
