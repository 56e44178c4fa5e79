"""The lamp's pose on the flange from the captures: the light's hand-eye calibration (docs/design.md §11).

Capture k was taken with the nominal light frame at a_k with rotation R_k (forward kinematics of the
plan's joint angles, ``[robot] light_offset_m``, ``light_rpy_deg``). A lamp mounted off its nominal
pose sits at

    p_k = a_k + R_k δ,

with δ (m) its offset in the nominal light frame, the same for every capture; δ = (δ_x, δ_y, 0) is
estimated, across the lamp's axis (below: why not along it). Lit pixel p (point x_p,
normal n_p, albedo ρ_p) of the linearised capture k then reads

    L_kp = c_p ρ_p (A S_kp + B),    S_kp = v_kp max(0, n_p·l_kp) f_kp,

with l = (p_k − x_p)/r, r = |p_k − x_p|, f = (b/r)² for the point model (l = (p_k − O)/|p_k − O|,
f = 1, for the directional one); v is the cast-shadow visibility at the nominal positions (the
entries near shadow edges are left out).

(δ_x, δ_y, B) minimise Σ (L − L̂)² over the entries the photometric fit used (its γ and A; at most
:data:`MAX_PIXELS` pixels, evenly spaced), each pixel's factor c_p eliminated in closed form
(variable projection: c_p = Σ_k L m / Σ_k m², m = ρ (A S + B), so that only how a pixel's value
changes from light to light, the shading's geometry, decides δ), by scipy's trust-region least
squares with Kaufman's Jacobian built from the analytic ∂S/∂δ (:func:`lamp_shading`, checked
against finite differences in ``tests/capture/test_lamp.py``). The uncertainty is the Gauss–Newton
covariance σ² (JᵀJ)⁺ with σ² = Σ r² / (N − n), a lower bound: model errors (gloss,
inter-reflection) are correlated across pixels. A component whose 2σ exceeds its plausible range
(:data:`PLAUSIBLE_M`) is reported unidentifiable and not applied.

Not estimated, and why:

- the offset along the lamp's axis (δ_z): it changes only the lamp's distance from the object, whose
  effect on the images (brighter by (b/r)², the near parts a little more) the power, the response γ
  and the falloff absorb together. Fitted with them by alternation it drifted along that valley
  (a 3 cm lateral offset came out with δ_z = +33 mm and γ 2.52 for 2.2), while the covariance at a
  fixed γ claimed ±0.6 mm; a profile of the photometric fit's cost over δ_z (γ, A, B, c refitted at
  each δ_z) put a 10 mm axial offset at 6.5 mm with a curvature 1σ of 0.04 mm. δ_z keeps its
  nominal 0;
- the emitting radius: a sphere of uniform radiance lights an unoccluded Lambertian point exactly
  as a point at its centre does, and a Lambertian disk of radius R facing the object differs from it
  by the factor (1 + R²/r²)⁻¹ (0.14 % for R = 1.5 cm at r = 0.4 m), far below the fit's residual; only
  penumbrae and the horizon carry R, the entries the fit leaves out;
- the tilt of the lamp's axis: it shows only through the lamp's emission profile across an object
  that subtends a few degrees of the beam, which the falloff, the response γ and the axial offset
  mimic. A fit of the tilt with an emission exponent e = (−u·l)^m drove an isotropic lamp to m ≈ 1.6
  and its axial offset 8 cm off; the tilt keeps its nominal value.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import least_squares

from optlight.capture import Array
from optlight.scene import Scene

#: The offset's components estimated, in the light frame (across the lamp's axis).
AXES = ("x", "y")
#: Plausible range (width, m) of each component: a lamp mounted within 5 cm of its nominal pose.
PLAUSIBLE_M = 0.05
#: Bound of the fit: each component within this fraction of the light sphere's radius.
OFFSET_BOUND = 0.5
#: At most this many pixels enter the fit (evenly spaced over the object).
MAX_PIXELS = 4000


@dataclass(frozen=True, eq=False)
class LampGeometry:
    """What the lamp fit holds fixed: surface ``points`` and ``normals`` (P, 3) of the fitted pixels,
    the nominal light frames' positions (K, 3) and ``rotations`` (K, 3, 3), the cast-shadow
    ``visibility`` (K, P), the light ``model``, the light sphere's ``center`` O and ``radius`` b."""

    points: Array
    normals: Array
    positions: Array
    rotations: Array
    visibility: Array
    model: Literal["directional", "point"]
    center: Array
    radius: float


def lamp_shading(offset: Array, geometry: LampGeometry) -> tuple[Array, Array]:
    """S_kp (K, P) of the module docstring for the lamp's offset δ (3,), m, and ∂S/∂δ (K, P, 3).

    With d = p − x, r = |d|, l = d/r (``u`` in the code): ∂l/∂p = (I − l lᵀ)/r, so
    ∂(n·l)/∂p = (n − (n·l) l)/r, ∂f/∂p = −2 f l / r, and ∂p/∂δ = R_k. The directional model's
    l = (p − O)/|p − O| has no falloff."""
    g = geometry
    p = g.positions + np.einsum("kij,j->ki", g.rotations, np.asarray(offset, float))  # (K, 3)
    if g.model == "directional":
        d = p - g.center
        r = np.linalg.norm(d, axis=1)
        u = d / r[:, None]
        cos = u @ g.normals.T  # (K, P)
        lit = (cos > 0) * g.visibility
        dcos_dp = (g.normals[None, :, :] - cos[:, :, None] * u[:, None, :]) / r[:, None, None]
        return lit * cos, np.einsum("kpi,kij->kpj", lit[..., None] * dcos_dp, g.rotations)
    d = p[:, None, :] - g.points[None, :, :]  # (K, P, 3)
    r = np.linalg.norm(d, axis=2)
    u = d / r[..., None]
    cos = np.einsum("kpi,pi->kp", u, g.normals)
    falloff = g.radius**2 / (r * r)
    lit = (cos > 0) * g.visibility
    dcos = (g.normals[None] - cos[..., None] * u) / r[..., None]
    dfall = -2.0 * falloff[..., None] * u / r[..., None]
    dshade_dp = lit[..., None] * (dcos * falloff[..., None] + dfall * cos[..., None])
    return lit * cos * falloff, np.einsum("kpi,kij->kpj", dshade_dp, g.rotations)


@dataclass(frozen=True)
class LampCalibration:
    """The lamp's estimated offset on the flange (module docstring): ``estimate_m`` (δ_x, δ_y) and
    ``std_m`` (1σ) per light-frame axis across the lamp's axis (m), ``identifiable`` per axis (2σ within :data:`PLAUSIBLE_M`), the fitted
    ``ambient_ratio`` B/A, the ``residual_rms`` of the linearised values (renderer units), the
    ``entries`` and ``captures`` fitted and the light ``model``."""

    estimate_m: tuple[float, float]
    std_m: tuple[float, float]
    identifiable: tuple[bool, bool]
    ambient_ratio: float
    residual_rms: float
    entries: int
    captures: int
    model: Literal["directional", "point"]

    @property
    def offset_m(self) -> Array:
        """δ (3,), light frame, m: the identifiable lateral components, 0 for the others and along the
        axis."""
        return np.array([*np.where(self.identifiable, self.estimate_m, 0.0), 0.0])

    def positions(self, positions: Array, rotations: Array) -> Array:
        """The lamp's positions a_k + R_k δ (K, 3) for nominal light frames at ``positions`` (K, 3)
        with ``rotations`` (K, 3, 3)."""
        return np.asarray(positions, float) + np.einsum("kij,j->ki", np.asarray(rotations, float), self.offset_m)

    def to_dict(self) -> dict[str, Any]:
        """JSON-safe: the offset per axis (estimate, 1σ, identifiable and so applied), what is not
        estimated and why, and the fit's statistics."""
        return {
            "offset_m": {
                axis: {"estimate": value, "std": std if np.isfinite(std) else None, "identifiable": ok}
                for axis, value, std, ok in zip(AXES, self.estimate_m, self.std_m, self.identifiable, strict=True)
            },
            "applied_offset_m": self.offset_m.tolist(),
            "plausible_range_m": PLAUSIBLE_M,
            "frame": "nominal light frame ([robot] light_offset_m, light_rpy_deg; +z towards the object)",
            "not_estimated": {
                "radius_m": "an emitter of radius R lights an unoccluded Lambertian point as a point at its "
                "centre to (1 + R²/r²)⁻¹; only penumbrae carry R, which the fit leaves out",
                "offset_z_m": "along the lamp's axis the offset changes only the distance, which the power, the "
                "response γ and the falloff absorb together (alternating fits drifted along that valley)",
                "tilt_deg": "seen only through the emission profile over a few degrees of the beam, which the "
                "falloff, γ and the axial offset mimic",
            },
            "light_model": self.model,
            "ambient_ratio": self.ambient_ratio,
            "residual_rms": self.residual_rms,
            "entries": self.entries,
            "captures": self.captures,
        }

    def summary(self) -> str:
        """One line: the lateral offset per axis (mm) with its 1σ, unidentifiable axes named."""
        parts = [
            f"{axis} {1e3 * value:+.1f} ± {1e3 * std:.1f} mm" if ok else f"{axis} unidentifiable"
            for axis, value, std, ok in zip(AXES, self.estimate_m, self.std_m, self.identifiable, strict=True)
        ]
        return "lamp offset on the flange (light frame): " + ", ".join(parts) + " (along the axis: not estimated)"


def fit_lamp(
    scene: Scene,
    linear: Array,
    weights: NDArray[np.bool_],
    positions: Array,
    rotations: Array,
    albedo: Array,
    power_gain: float,
    ambient_gain: float,
) -> LampCalibration:
    """Fit the lamp's offset (module docstring) to the linearised values ``linear`` (K, P) on the
    entries ``weights`` (K, P), for nominal light frames at ``positions`` (K, 3) with ``rotations``
    (K, 3, 3), the albedo ``albedo`` ρ (P,), the photometric fit's A (held) and B (the start).
    ``scene``'s light model is the one fitted."""
    pixels = _fit_pixels(weights)
    gb = scene.gbuffer
    geometry = LampGeometry(
        points=gb.points[pixels],
        normals=gb.normals[pixels],
        positions=np.asarray(positions, float),
        rotations=np.asarray(rotations, float),
        visibility=np.array([scene.visibility(a)[pixels] for a in positions]),
        model=scene.light.model,
        center=np.asarray(scene.sphere.center, float),
        radius=float(scene.sphere.radius),
    )
    w = weights[:, pixels].astype(float)
    y, rho = linear[:, pixels], albedo[pixels]
    mask = w > 0

    def model(x: Array) -> tuple[Array, Array, Array]:
        """m = ρ (A S + B) (K, P), ∂m/∂(δ_x, δ_y, B) (K, P, 3) and each pixel's least-squares factor
        c (P,)."""
        shade, dshade = lamp_shading(np.array([x[0], x[1], 0.0]), geometry)
        m = rho * (power_gain * shade + x[2])
        dm = rho[None, :, None] * np.concatenate([power_gain * dshade[..., :2], np.ones((*shade.shape, 1))], axis=2)
        den = (w * m * m).sum(axis=0)
        c = np.where(den > 0, (w * y * m).sum(axis=0) / np.where(den > 0, den, 1.0), 0.0)
        return m, dm, c

    def residual(x: Array) -> Array:
        m, _, c = model(x)
        return (c * m - y)[mask]

    def jacobian(x: Array) -> Array:
        """Kaufman's variable-projection Jacobian: c ∂m/∂θ less its projection on m per pixel (the
        direction c absorbs)."""
        m, dm, c = model(x)
        den = (w * m * m).sum(axis=0)
        along = np.einsum("kp,kpj->pj", w * m, dm) / np.where(den > 0, den, 1.0)[:, None]
        return (c[None, :, None] * (dm - m[..., None] * along[None]))[mask]

    b = OFFSET_BOUND * geometry.radius
    result = least_squares(
        residual,
        np.array([0.0, 0.0, ambient_gain]),
        jac=jacobian,
        bounds=([-b, -b, -np.inf], [b, b, np.inf]),
        x_scale="jac",
        method="trf",
    )
    std = _standard_errors(result.fun, jacobian(result.x))[:2]
    return LampCalibration(
        estimate_m=(float(result.x[0]), float(result.x[1])),
        std_m=(float(std[0]), float(std[1])),
        identifiable=(bool(2 * std[0] <= PLAUSIBLE_M), bool(2 * std[1] <= PLAUSIBLE_M)),
        ambient_ratio=float(result.x[2] / power_gain),
        residual_rms=float(np.sqrt(np.mean(result.fun**2))),
        entries=int(mask.sum()),
        captures=int(len(positions)),
        model=geometry.model,
    )


def _fit_pixels(weights: NDArray[np.bool_]) -> NDArray[np.intp]:
    """The pixels used by some entry, at most :data:`MAX_PIXELS` of them, evenly spaced."""
    used = np.flatnonzero(weights.any(axis=0))
    if used.size <= MAX_PIXELS:
        return used
    return used[np.linspace(0, used.size - 1, MAX_PIXELS).round().astype(np.intp)]


def _standard_errors(residual: Array, jacobian: Array) -> Array:
    """1σ of each parameter from the Gauss–Newton covariance σ² (JᵀJ)⁺, σ² = Σ r² / (N − n); ∞ for a
    parameter in a direction JᵀJ does not see (a singular value of the column-scaled JᵀJ below 1e-10 of
    the largest)."""
    n_entries, n = jacobian.shape
    sigma2 = float(residual @ residual) / max(n_entries - n, 1)
    jtj = jacobian.T @ jacobian
    scale = np.sqrt(np.maximum(np.diag(jtj), 1e-300))
    u, s, vt = np.linalg.svd(jtj / np.outer(scale, scale))
    keep = s > 1e-10 * s[0]
    inverse = (vt[keep].T / s[keep]) @ u[:, keep].T
    variance = np.diag(inverse) / scale**2 * sigma2
    blind = np.abs(vt[~keep]).max(axis=0) > 1e-3 if (~keep).any() else np.zeros(n, bool)
    return np.where(blind, np.inf, np.sqrt(np.maximum(variance, 0.0)))
