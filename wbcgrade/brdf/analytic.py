"""Analytic, physically based BRDF models: a deterministic synthetic database.

No measured BRDF database can be downloaded here, so ``default_materials``
builds one from classic models, all evaluated with numpy on arrays of
direction pairs in the local frame (z = surface normal, x = tangent):

- ``Lambert``: ideal diffuse, ``albedo / pi``.
- ``GGXConductor``: Cook-Torrance microfacet metal with the GGX (Trowbridge-
  Reitz) distribution, separable Smith shadowing and Schlick's Fresnel with a
  coloured normal-incidence reflectance ``f0``.
- ``GGXPlastic``: a Lambertian base under a dielectric GGX coat (``f0`` = 0.04,
  index 1.5); the base is weighted by the coat's transmission ``1 - F``.
- ``Ward``: Ward's anisotropic Gaussian lobe (roughness ``alpha_x`` along the
  tangent, ``alpha_y`` along the bitangent) plus a diffuse term.

Every ``evaluate(incoming, outgoing)`` returns finite, non-negative values of
shape ``(..., 3)`` (RGB, 1/sr). Directions below the horizon are evaluated as
if mirrored above it (|cos| floored at 1e-4), so that tabulating onto the MERL
grid, which has bins straddling the horizon, gives finite values everywhere.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from wbcgrade.errors import InputError, OptionError

_MIN_COS = 1e-4


def _cosines(incoming: np.ndarray, outgoing: np.ndarray):
    incoming = np.asarray(incoming, dtype=np.float64)
    outgoing = np.asarray(outgoing, dtype=np.float64)
    cos_in = np.maximum(np.abs(incoming[..., 2]), _MIN_COS)
    cos_out = np.maximum(np.abs(outgoing[..., 2]), _MIN_COS)
    half = incoming + outgoing
    norm = np.linalg.norm(half, axis=-1, keepdims=True)
    half = half / np.maximum(norm, 1e-12)
    half = np.where(half[..., 2:3] < 0.0, -half, half)
    cos_half = np.clip(half[..., 2], 0.0, 1.0)
    cos_diff = np.clip(np.abs(np.sum(incoming * half, axis=-1)), 0.0, 1.0)
    return cos_in, cos_out, half, cos_half, cos_diff


def _ggx_distribution(cos_half: np.ndarray, alpha: float) -> np.ndarray:
    a2 = alpha * alpha
    denominator = cos_half * cos_half * (a2 - 1.0) + 1.0
    return a2 / (np.pi * denominator * denominator)


def _smith_g1(cos_theta: np.ndarray, alpha: float) -> np.ndarray:
    a2 = alpha * alpha
    return 2.0 * cos_theta / (cos_theta + np.sqrt(a2 + (1.0 - a2) * cos_theta * cos_theta))


def _schlick(f0: np.ndarray, cos_diff: np.ndarray) -> np.ndarray:
    return f0 + (1.0 - f0) * ((1.0 - cos_diff) ** 5)[..., None]


def _rgb(value, name: str) -> np.ndarray:
    array = np.asarray(value, dtype=np.float64).reshape(-1)
    if array.shape != (3,) or not np.all(np.isfinite(array)) or np.any(array < 0):
        raise InputError(f"{name} must be three non-negative numbers, got {value!r}")
    return array


def _alpha(value: float, name: str) -> float:
    value = float(value)
    if not (0.0 < value <= 1.0):
        raise InputError(f"{name} must be in (0, 1], got {value}")
    return value


@dataclass(frozen=True)
class Lambert:
    """Ideal diffuse reflector, ``f = albedo / pi``."""

    name: str
    albedo: tuple[float, float, float]
    isotropic: bool = True

    def evaluate(self, incoming: np.ndarray, outgoing: np.ndarray) -> np.ndarray:
        """BRDF values, shape (..., 3), for direction pairs of shape (..., 3)."""
        shape = np.broadcast_shapes(np.shape(incoming), np.shape(outgoing))[:-1]
        return np.broadcast_to(_rgb(self.albedo, "albedo") / np.pi, (*shape, 3)).copy()


@dataclass(frozen=True)
class GGXConductor:
    """Cook-Torrance metal: ``D_GGX(h) G(i, o) F_schlick(f0, i.h) / (4 cos_i cos_o)``."""

    name: str
    f0: tuple[float, float, float]
    roughness: float
    isotropic: bool = True

    def evaluate(self, incoming: np.ndarray, outgoing: np.ndarray) -> np.ndarray:
        """BRDF values, shape (..., 3), for direction pairs of shape (..., 3)."""
        alpha = _alpha(self.roughness, "roughness")
        cos_in, cos_out, _, cos_half, cos_diff = _cosines(incoming, outgoing)
        specular = (
            _ggx_distribution(cos_half, alpha)
            * _smith_g1(cos_in, alpha) * _smith_g1(cos_out, alpha)
            / (4.0 * cos_in * cos_out)
        )
        return specular[..., None] * _schlick(_rgb(self.f0, "f0"), cos_diff)


@dataclass(frozen=True)
class GGXPlastic:
    """Diffuse base under a GGX dielectric coat (``f0`` = 0.04)."""

    name: str
    albedo: tuple[float, float, float]
    roughness: float
    coat: float = 1.0
    isotropic: bool = True

    def evaluate(self, incoming: np.ndarray, outgoing: np.ndarray) -> np.ndarray:
        """BRDF values, shape (..., 3), for direction pairs of shape (..., 3)."""
        alpha = _alpha(self.roughness, "roughness")
        cos_in, cos_out, _, cos_half, cos_diff = _cosines(incoming, outgoing)
        fresnel = _schlick(np.full(3, 0.04), cos_diff)
        specular = (
            _ggx_distribution(cos_half, alpha)
            * _smith_g1(cos_in, alpha) * _smith_g1(cos_out, alpha)
            / (4.0 * cos_in * cos_out)
        )
        diffuse = _rgb(self.albedo, "albedo") / np.pi * (1.0 - fresnel)
        return diffuse + float(self.coat) * specular[..., None] * fresnel


@dataclass(frozen=True)
class Ward:
    """Ward's anisotropic model.

    ``f = rho_d / pi + rho_s exp(-tan^2(theta_h) (cos^2 phi_h / ax^2 + sin^2 phi_h / ay^2))
    / (4 pi ax ay sqrt(cos_i cos_o))``.
    """

    name: str
    diffuse: tuple[float, float, float]
    specular: tuple[float, float, float]
    alpha_x: float
    alpha_y: float

    @property
    def isotropic(self) -> bool:
        return self.alpha_x == self.alpha_y

    def evaluate(self, incoming: np.ndarray, outgoing: np.ndarray) -> np.ndarray:
        """BRDF values, shape (..., 3), for direction pairs of shape (..., 3)."""
        ax = _alpha(self.alpha_x, "alpha_x")
        ay = _alpha(self.alpha_y, "alpha_y")
        cos_in, cos_out, half, _, _ = _cosines(incoming, outgoing)
        hz = np.maximum(half[..., 2], _MIN_COS)
        exponent = -((half[..., 0] / ax) ** 2 + (half[..., 1] / ay) ** 2) / (hz * hz)
        lobe = np.exp(exponent) / (4.0 * np.pi * ax * ay * np.sqrt(cos_in * cos_out))
        return (_rgb(self.diffuse, "diffuse") / np.pi
                + lobe[..., None] * _rgb(self.specular, "specular"))


Material = Lambert | GGXConductor | GGXPlastic | Ward

_CATALOGUE: tuple[Material, ...] = (
    GGXConductor("gold-ggx-0.15", (1.00, 0.77, 0.34), 0.15),
    GGXPlastic("red-plastic-ggx-0.20", (0.60, 0.07, 0.05), 0.20),
    Ward("brushed-steel-ward", (0.02, 0.02, 0.02), (0.55, 0.55, 0.58), 0.08, 0.35),
    Lambert("white-lambert", (0.80, 0.80, 0.76)),
    GGXConductor("copper-ggx-0.35", (0.95, 0.64, 0.54), 0.35),
    GGXPlastic("blue-plastic-ggx-0.45", (0.05, 0.15, 0.55), 0.45),
    GGXConductor("aluminium-ggx-0.08", (0.91, 0.92, 0.92), 0.08),
    Ward("green-satin-ward", (0.05, 0.25, 0.08), (0.25, 0.30, 0.25), 0.15, 0.50),
    GGXPlastic("yellow-plastic-ggx-0.10", (0.65, 0.55, 0.05), 0.10),
    GGXConductor("silver-ggx-0.55", (0.97, 0.96, 0.91), 0.55),
    Lambert("clay-lambert", (0.45, 0.25, 0.15)),
    GGXPlastic("black-plastic-ggx-0.25", (0.02, 0.02, 0.02), 0.25),
)

_HELD_OUT: tuple[Material, ...] = (
    GGXPlastic("orange-plastic-ggx-0.30", (0.70, 0.30, 0.05), 0.30),
    GGXConductor("bronze-ggx-0.25", (0.80, 0.55, 0.35), 0.25),
    Ward("brushed-gold-ward", (0.03, 0.02, 0.01), (0.80, 0.60, 0.30), 0.10, 0.30),
)


def default_materials(count: int = 6) -> list[Material]:
    """The first ``count`` materials of the built-in catalogue (deterministic).

    Beyond the 12 catalogue entries, variations are drawn with a fixed seed
    (random GGX plastics and conductors), so any ``count`` is reproducible.
    """
    count = int(count)
    if count < 1:
        raise InputError(f"a database needs at least one material, got --count {count}")
    materials = list(_CATALOGUE[:count])
    rng = np.random.default_rng(20160724)
    while len(materials) < count:
        index = len(materials)
        colour = tuple(float(v) for v in rng.uniform(0.05, 0.9, 3))
        roughness = float(np.round(rng.uniform(0.08, 0.6), 2))
        if index % 2:
            materials.append(GGXConductor(f"conductor-{index:02d}-ggx-{roughness}", colour,
                                          roughness))
        else:
            materials.append(GGXPlastic(f"plastic-{index:02d}-ggx-{roughness}", colour,
                                        roughness))
    return materials


def held_out_materials() -> list[Material]:
    """Materials that are not in any ``default_materials`` database (for references)."""
    return list(_HELD_OUT)


def material_by_name(name: str) -> Material:
    """A catalogue or held-out material by its name."""
    for material in (*_CATALOGUE, *_HELD_OUT):
        if material.name == name:
            return material
    known = ", ".join(m.name for m in (*_CATALOGUE, *_HELD_OUT))
    raise OptionError(f"{{material}} {name!r} is unknown; known: {known}", "material")


def all_material_names() -> list[str]:
    """Names of the catalogue materials followed by the held-out ones."""
    return [m.name for m in (*_CATALOGUE, *_HELD_OUT)]


def sample_material(material: Material, directions: np.ndarray) -> np.ndarray:
    """A material's BRDF on a hemisphere sampling.

    Parameters
    ----------
    material : Lambert | GGXConductor | GGXPlastic | Ward
    directions : ndarray, shape (N, 3)

    Returns
    -------
    values : ndarray, shape (N, N, 3)
        ``values[a, b]`` = BRDF from ``directions[a]`` (incoming) to ``directions[b]``.
    """
    directions = np.asarray(directions, dtype=np.float64)
    return material.evaluate(directions[:, None, :], directions[None, :, :])
