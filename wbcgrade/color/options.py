"""Settings of a grade: small frozen groups, each validated once, when it is made.

A grade is set by five groups (:class:`GradeOptions` holds one of each):

- :class:`FitOptions` (``fit``): the barycentric weights, fitted on a coarse grid;
- :class:`TransferOptions` (``transfer``): the photo's histogram, the palette
  and the transport plan on the transfer grid;
- :class:`MapOptions` (``map``): how the colour map is built (``builder``),
  smoothed and finished (monotone lightness, kept lightness, strength);
- :class:`RegrainOptions` (``regrain``): the input's grain and edges given back;
- :class:`SpaceOptions` (``spaces``): the input and working colour spaces.

Every group is a frozen dataclass: once made it is valid and cannot change
(derive another with :func:`dataclasses.replace`, which validates the new
one). A value out of range raises :class:`~wbcgrade.errors.OptionError`
naming the field as ``group.field`` (e.g. ``transfer.bins``); the command
line maps fields to its flags (``wbcgrade/cli/grading_options.py``).

The former flat settings (``GradeOptions(bins=64, relaxation=0.05)``, the
names of the command-line options' parameters) are still accepted and
sorted into the groups (:data:`FLAT_FIELDS`).

>>> from wbcgrade.color.options import GradeOptions, TransferOptions
>>> opts = GradeOptions(transfer=TransferOptions(bins=64, relaxation=0.05))
>>> opts.transfer.bins, opts.fit.bins, opts.map.builder
(64, 16, 'look')
>>> GradeOptions(bins=64, relaxation=0.05) == opts  # the former flat names
True
>>> GradeOptions(strength=5)
Traceback (most recent call last):
...
wbcgrade.errors.OptionError: map.strength must be in [0, 4]
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields

from wbcgrade.errors import OptionError
from wbcgrade.limits import (
    MAX_BARYCENTER_ITERATIONS,
    MAX_REGRAIN_EPS,
    MAX_REGRAIN_RADIUS,
    MIN_REGRAIN_EPS,
)

__all__ = ["LOSSES", "MODES", "FitOptions", "TransferOptions", "MapOptions", "RegrainOptions",
           "SpaceOptions", "GradeOptions", "FLAT_FIELDS", "flat_defaults", "as_options",
           "DEFAULT_FLOOR",
           "DEFAULT_MAX_PIXELS", "DEFAULT_MAP_SIZE", "DEFAULT_SMOOTHNESS", "DEFAULT_STIFFNESS",
           "DEFAULT_REGRAIN_RADIUS", "DEFAULT_REGRAIN_EPS"]

#: Losses the weight fit may use (``wbcgrade.core.get_loss`` names).
LOSSES = ("quadratic", "l1", "kl", "wasserstein")
#: The shipped map builders (``map.builder``): "palette", the paper's
#: colour transfer onto the closest barycenter of the style palettes; "look", the
#: look the style set shares, corrected towards the photo's own scene.
MODES = ("look", "palette")
#: The largest ``map.strength``: above 1 a grade's displacement is scaled up.
MAX_STRENGTH = 4.0
#: Fraction of mass spread uniformly over every histogram before fitting (real
#: photo histograms are sparse; KL needs > 0).
DEFAULT_FLOOR = 1e-4
#: Photos larger than this are subsampled for their histograms.
DEFAULT_MAX_PIXELS = 262_144
#: Nodes per axis of the smooth colour map (the grade is this lattice LUT).
DEFAULT_MAP_SIZE = 33
#: Curvature penalty of the smooth map (relative to the data term).
DEFAULT_SMOOTHNESS = 3e-3
#: First-difference penalty of the smooth map (holds its local gain near 1).
DEFAULT_STIFFNESS = 1e-4
#: Regrain window radius as a fraction of the image's long side (5 px at 1024 px).
DEFAULT_REGRAIN_RADIUS = 1.0 / 200.0
#: Regrain regulariser in squared encoded units: input variations well below
#: sqrt(eps) = 0.2 (grain, JPEG blocks, gentle gradients) keep their amplitude.
DEFAULT_REGRAIN_EPS = 0.04  # (0.2 squared, written as typed: the help shows it)


def _fail(name: str, why: str) -> OptionError:
    return OptionError(f"{{{name}}} {why}", name)


def _int_in(group: str, name: str, value, low: int, high: int) -> None:
    if isinstance(value, bool) or not isinstance(value, int) or not low <= value <= high:
        raise _fail(f"{group}.{name}", f"must be between {low} and {high}")


def _positive(group: str, name: str, value, optional: bool = False) -> None:
    if value is None and optional:
        return
    if not isinstance(value, (int, float)) or not (math.isfinite(value) and value > 0):
        raise _fail(f"{group}.{name}", "must be positive")


def _non_negative(group: str, name: str, value) -> None:
    if not isinstance(value, (int, float)) or not (math.isfinite(value) and value >= 0):
        raise _fail(f"{group}.{name}", "must be a non-negative number")


def _fraction(group: str, name: str, value, closed: bool = True) -> None:
    ok = isinstance(value, (int, float)) and math.isfinite(value) and value >= 0 and (
        value <= 1 if closed else value < 1)
    if not ok:
        raise _fail(f"{group}.{name}", "must be in [0, 1]" if closed else "must be in [0, 1)")


@dataclass(frozen=True)
class FitOptions:
    """The weight fit: barycentric coordinates of the photo's histogram.

    Attributes
    ----------
    bins : bins per axis of the fit grid (the kernel's sigma is fixed in colour
        units, so the same energy on a 128^3 grid has the same minimiser:
        the apply benchmark's verification).
    loss : loss between the barycenter and the photo's histogram (:data:`LOSSES`).
    width : kernel width in bins of the fit grid (gamma = 2 (width / (bins - 1))^2).
    gamma : entropic regularisation; overrides ``width`` when given.
    n_iter : barycenter iterations L (the palette uses the same L).
    max_iter : L-BFGS iterations at most.
    tol : the fit stops when an L-BFGS step lowers the (normalised) loss by less.
    floor : uniform mass mixed into every fit histogram.
    weights : fixed style weights (no fit; normalised to sum 1), or None.
    """

    bins: int = 16
    loss: str = "quadratic"
    width: float = 1.5
    gamma: float | None = None
    n_iter: int = 60
    max_iter: int = 30
    tol: float = 1e-6
    floor: float = DEFAULT_FLOOR
    weights: tuple[float, ...] | None = None

    def __post_init__(self) -> None:
        _int_in("fit", "bins", self.bins, 4, 256)
        if self.loss not in LOSSES:
            raise _fail("fit.loss", f"must be one of {', '.join(LOSSES)}")
        _positive("fit", "width", self.width)
        _positive("fit", "gamma", self.gamma, optional=True)
        for name in ("n_iter", "max_iter"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise _fail(f"fit.{name}", "must be at least 1")
        _int_in("fit", "n_iter", self.n_iter, 1, MAX_BARYCENTER_ITERATIONS)
        _positive("fit", "tol", self.tol)
        _fraction("fit", "floor", self.floor, closed=False)
        if self.weights is not None:
            values = tuple(float(w) for w in self.weights)
            if not values or any(not math.isfinite(w) or w < 0 for w in values) \
                    or max(values) <= 0:
                raise _fail("fit.weights", "must be non-negative finite numbers, not all zero")
            object.__setattr__(self, "weights", values)

    @property
    def kernel_gamma(self) -> float:
        """The fit kernel's gamma (``gamma``, else from ``width``)."""
        if self.gamma is not None:
            return float(self.gamma)
        return 2.0 * (self.width / (self.bins - 1)) ** 2


@dataclass(frozen=True)
class TransferOptions:
    """The transfer grid: the photo's histogram, the palette and the transport plan.

    Attributes
    ----------
    bins : bins per axis of the transfer grid (the paper's 128).
    palette_bins : the palette (barycenter) is computed on at most this many
        bins per axis and interpolated onto the transfer grid (its kernel is
        >= 2 bins wide there, so it is resolved; 128^3 costs 8x more).
    width : kernel width in bins of the transfer grid; None: sigma = 1/31 of
        the colour cube whatever the grid (``max(1, (bins - 1) / 31)`` bins).
    tol, max_iter : Sinkhorn stopping rule (L1 error on the photo's
        marginal). 3e-3 gives the same smooth colour map as 1e-3 within a fraction
        of 1/255, in half the time (docs/benchmarks.md).
    relaxation : rho > 0 relaxes the palette side of the plan by ``rho KL``
        (unbalanced transport: palette colours the photo has no use for are
        left out); None: balanced.
    floor : uniform mass mixed into the palette and the plan's marginals.
    max_pixels : photos larger than this are subsampled for their
        histograms (on the transfer and the fit grid).
    """

    bins: int = 128
    palette_bins: int = 64
    width: float | None = None
    tol: float = 3e-3
    max_iter: int = 2000
    relaxation: float | None = None
    floor: float = DEFAULT_FLOOR
    max_pixels: int = DEFAULT_MAX_PIXELS

    def __post_init__(self) -> None:
        _int_in("transfer", "bins", self.bins, 4, 256)
        _int_in("transfer", "palette_bins", self.palette_bins, 4, 256)
        _positive("transfer", "width", self.width, optional=True)
        _positive("transfer", "tol", self.tol)
        _int_in("transfer", "max_iter", self.max_iter, 1, 10 ** 9)
        _positive("transfer", "relaxation", self.relaxation, optional=True)
        _fraction("transfer", "floor", self.floor, closed=False)
        _int_in("transfer", "max_pixels", self.max_pixels, 1, 10 ** 12)

    @property
    def width_bins(self) -> float:
        """The transfer kernel's width in bins (``width``, else 1/31 of the cube)."""
        if self.width is not None:
            return float(self.width)
        return max(1.0, (self.bins - 1) / 31.0)


@dataclass(frozen=True)
class MapOptions:
    """The colour map: how it is built, smoothed and finished.

    Attributes
    ----------
    builder : how the map is built (a name registered with
        :func:`wbcgrade.color.grade.grading.register_map_builder`; :data:`MODES`:
        "look" (the default): the look the style set shares, or the look read
        off the style photos that show the photo's own scene
        (:mod:`wbcgrade.color.look.scene`); "palette": the fitted barycenter
        palette, (unbalanced) Sinkhorn, smooth map, the paper's colour transfer).
    natural : preset file (.npz) of ungraded photos, or a folder of the user's own
        ungraded photos, the content model of the "look" builder; None: the shipped one.
    size : nodes per axis of the smooth colour map (the grade is this lattice
        LUT; a LUT written at the same size holds it exactly).
    smoothness, stiffness : curvature and first-difference penalties of the
        smooth map fit (:mod:`wbcgrade.color.palette.smooth_map`); both 0: the raw
        barycentric projection on the transfer grid is the map (the paper's).
    monotone : make the map's output luma non-decreasing in each input
        channel (the working space's luma, :attr:`ColorEncoding.luma_weights`).
    preserve_luminance : keep each colour's Oklab lightness (computed in the
        working space's own terms), change only its hue and chroma.
    strength : t in [0, :data:`MAX_STRENGTH`]: x -> (1 - t) x + t T(x); above 1 the
        map's displacement itself is scaled by t (a faint look made stronger), clipped
        to the cube.
    """

    builder: str = "look"
    natural: str | None = None
    size: int = DEFAULT_MAP_SIZE
    smoothness: float = DEFAULT_SMOOTHNESS
    stiffness: float = DEFAULT_STIFFNESS
    monotone: bool = True
    preserve_luminance: bool = False
    strength: float = 1.0

    def __post_init__(self) -> None:
        if not isinstance(self.builder, str) or not self.builder:
            raise _fail("map.builder", "must name a map builder")
        if self.natural is not None and (not isinstance(self.natural, str) or not self.natural):
            raise _fail("map.natural", "must name a preset file")
        _int_in("map", "size", self.size, 2, 129)
        _non_negative("map", "smoothness", self.smoothness)
        _non_negative("map", "stiffness", self.stiffness)
        strength = self.strength
        if not (isinstance(strength, (int, float)) and math.isfinite(strength)
                and 0 <= strength <= MAX_STRENGTH):
            raise _fail("map.strength", f"must be in [0, {MAX_STRENGTH:g}]")

    @property
    def smoothed(self) -> bool:
        """Whether a smooth lattice map is fitted (else the raw projection is the map)."""
        return self.smoothness > 0 or self.stiffness > 0


@dataclass(frozen=True)
class RegrainOptions:
    """The regrain step (:func:`wbcgrade.color.mapping.remap.regrain`).

    Attributes
    ----------
    enabled : keep the input's grain and edges (off: every pixel goes exactly
        through the LUT).
    radius : window radius as a fraction of the photo's long side.
    eps : below this variance (encoded units squared) input detail is kept.
    """

    enabled: bool = True
    radius: float = DEFAULT_REGRAIN_RADIUS
    eps: float = DEFAULT_REGRAIN_EPS

    def __post_init__(self) -> None:
        _positive("regrain", "radius", self.radius)
        if self.radius > MAX_REGRAIN_RADIUS:
            raise _fail("regrain.radius", f"must be at most {MAX_REGRAIN_RADIUS:g} (a fraction "
                                          "of the photo's long side)")
        _positive("regrain", "eps", self.eps)
        if not MIN_REGRAIN_EPS <= self.eps <= MAX_REGRAIN_EPS:
            raise _fail("regrain.eps", f"must be between {MIN_REGRAIN_EPS:g} and "
                                       f"{MAX_REGRAIN_EPS:g} (squared encoded units: larger "
                                       "keeps no detail at all, smaller is below float32)")

    @property
    def settings(self) -> tuple[float, float] | None:
        """(radius, eps) when enabled, else None (what a Grade keeps)."""
        return (float(self.radius), float(self.eps)) if self.enabled else None


@dataclass(frozen=True)
class SpaceOptions:
    """Colour spaces (OpenColorIO names, aliases or roles; :mod:`wbcgrade.color.colorspace`).

    Attributes
    ----------
    input : the photos' space; None: what each file says (ICC profile, EXR
        metadata), else sRGB (8/16-bit) or Linear Rec.709 (float).
    working : where histograms, transport and the colour map live; None:
        sRGB-encoded Rec.709.
    """

    input: str | None = None
    working: str | None = None

    def __post_init__(self) -> None:
        for name in ("input", "working"):
            value = getattr(self, name)
            if value is not None and (not isinstance(value, str) or not value.strip()):
                raise _fail(f"spaces.{name}", "must name a colour space")


_GROUPS = {"fit": FitOptions, "transfer": TransferOptions, "map": MapOptions,
           "regrain": RegrainOptions, "spaces": SpaceOptions}

#: The former flat settings -> (group, field).
FLAT_FIELDS: dict[str, tuple[str, str]] = {
    "fit_bins": ("fit", "bins"), "loss": ("fit", "loss"), "width": ("fit", "width"),
    "gamma": ("fit", "gamma"), "n_iter": ("fit", "n_iter"), "max_iter": ("fit", "max_iter"),
    "fit_tol": ("fit", "tol"), "weights": ("fit", "weights"),
    "bins": ("transfer", "bins"), "palette_bins": ("transfer", "palette_bins"),
    "transfer_width": ("transfer", "width"), "sinkhorn_tol": ("transfer", "tol"),
    "sinkhorn_max_iter": ("transfer", "max_iter"), "relaxation": ("transfer", "relaxation"),
    "max_pixels": ("transfer", "max_pixels"),
    "mode": ("map", "builder"), "natural": ("map", "natural"),
    "map_size": ("map", "size"), "smoothness": ("map", "smoothness"),
    "stiffness": ("map", "stiffness"), "monotone": ("map", "monotone"),
    "preserve_luminance": ("map", "preserve_luminance"), "strength": ("map", "strength"),
    "regrain": ("regrain", "enabled"), "regrain_radius": ("regrain", "radius"),
    "regrain_eps": ("regrain", "eps"),
    "input_space": ("spaces", "input"), "working_space": ("spaces", "working"),
}


@dataclass(frozen=True, init=False)
class GradeOptions:
    """All the settings of a grade: one frozen, validated group each.

    ``GradeOptions()`` is every documented default. Groups are given whole
    (``GradeOptions(fit=FitOptions(loss="kl"))``), or by the former flat
    names (``GradeOptions(loss="kl", relaxation=0.05)``, :data:`FLAT_FIELDS`;
    ``floor`` sets both the fit's and the transfer's). Unknown names raise
    OptionError.

    Attributes
    ----------
    fit, transfer, map, regrain, spaces : the groups.
    """

    fit: FitOptions = field(default_factory=FitOptions)
    transfer: TransferOptions = field(default_factory=TransferOptions)
    map: MapOptions = field(default_factory=MapOptions)
    regrain: RegrainOptions = field(default_factory=RegrainOptions)
    spaces: SpaceOptions = field(default_factory=SpaceOptions)

    def __init__(self, fit: FitOptions | None = None, transfer: TransferOptions | None = None,
                 map: MapOptions | None = None, regrain: RegrainOptions | None = None,  # noqa: A002
                 spaces: SpaceOptions | None = None, **flat) -> None:
        if isinstance(regrain, bool):  # the former flat ``regrain=True/False``
            flat["regrain"], regrain = regrain, None
        given = {"fit": fit, "transfer": transfer, "map": map, "regrain": regrain,
                 "spaces": spaces}
        changes: dict[str, dict] = {name: {} for name in _GROUPS}
        for key, value in flat.items():
            if key == "floor":
                changes["fit"]["floor"] = changes["transfer"]["floor"] = value
                continue
            if key == "regrain":
                changes["regrain"]["enabled"] = value
                continue
            if key not in FLAT_FIELDS:
                raise OptionError(f"unknown grade option {key!r}", key)
            group, name = FLAT_FIELDS[key]
            changes[group][name] = value
        for name, kind in _GROUPS.items():
            group = given[name]
            if group is not None and not isinstance(group, kind):
                raise OptionError(f"{{{name}}} must be a {kind.__name__}", name)
            if changes[name]:
                base = {f.name: getattr(group, f.name) for f in fields(kind)} if group else {}
                group = kind(**{**base, **changes[name]})
            object.__setattr__(self, name, group if group is not None else kind())

    def flat(self) -> dict:
        """The settings under their former flat names (JSON-friendly; records, reports)."""
        out = {key: getattr(getattr(self, group), name)
               for key, (group, name) in FLAT_FIELDS.items()}
        out["floor"] = self.fit.floor
        if out["weights"] is not None:
            out["weights"] = list(out["weights"])
        return out

    def check_styles(self, n_styles: int) -> None:
        """OptionError when fixed weights do not give one number per style."""
        weights = self.fit.weights
        if weights is not None and len(weights) != n_styles:
            raise OptionError(f"{{fit.weights}} gives {len(weights)} numbers for {n_styles} styles",
                              "fit.weights")


def as_options(options: GradeOptions | None = None, **flat) -> GradeOptions:
    """``options`` (default :class:`GradeOptions()`), with flat names changed if given."""
    options = options if options is not None else GradeOptions()
    if not isinstance(options, GradeOptions):
        raise OptionError(f"{{options}} must be GradeOptions, got {type(options).__name__}",
                          "options")
    if not flat:
        return options
    return GradeOptions(options.fit, options.transfer, options.map, options.regrain,
                        options.spaces, **flat)



def flat_defaults() -> dict:
    """Every setting's default under its flat name, read from the fields (no option
    object is made, so nothing is validated: the command line shows these)."""
    defaults = {}
    for key, (group, name) in FLAT_FIELDS.items():
        spec = next(f for f in fields(_GROUPS[group]) if f.name == name)
        defaults[key] = spec.default
    return defaults
