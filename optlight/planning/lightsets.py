"""Light sets (docs/design.md §10): objectives that score N lights together, and their design.

A light set is N unit directions ``d_i`` from the object centre O towards the lights, in the light
sphere's frame S (docs/design.md §2: ``z_S`` towards the camera, so zenith 0 is frontal light). The decision
variables are the angles ``x = (θ_1 … θ_N, φ_1 … φ_N)`` (rad) with
``d_i = (sinθ_i cosφ_i, sinθ_i sinφ_i, cosθ_i)``, each zenith on the allowed cap
``θ_min ≤ θ_i ≤ θ_max`` (:class:`Cap`). ``D`` is the N×3 matrix whose rows are the ``d_i``.

Set terms (each a :class:`SetTerm`: a NumPy twin ``numpy(D, p)`` and a CasADi expression
``casadi(D, p)`` of an N×3 MX, with parameters ``p`` that are held fixed during a solve and recomputed
between solves, as the landmark search does with its visibility mask):

- :class:`UnshadowedTrace`: ``tr((DᵀD)⁻¹)``, the expected squared error of a Lambertian normal
  (times albedo) per unit noise for distant unit lights that all light the point. Since
  ``tr(DᵀD) = N``, ``tr((DᵀD)⁻¹) ≥ 9/N`` (arithmetic–harmonic means of its eigenvalues), with equality
  iff ``DᵀD = (N/3) I``: e.g. a ring at slant ``arccos(1/√3) = 54.7356°``.
- :class:`PhotometricStereoTerm`: the same per object pixel ``p`` over the lights that really light
  it, ``(1/P) Σ_p tr((D_pᵀ W_p D_p + εI)⁻¹)``, ``W_p = diag(w_p1 … w_pN)`` with the smooth weight

      w_pi = v_pi · S(β n_p·d_i) · S((ℓ − u_pi)/τ),

  ``n_p`` the G-buffer normal (sphere frame), ``v_pi ∈ {0, 1}`` the cast-shadow visibility (shadow
  rays; the parameters), ``S(x) = ½(1 + tanh(x/2))`` the logistic sigmoid, ``β`` the light's
  ``softplus_sharpness`` (attached shadow: ``n·d > 0``), and
  ``u_pi = g ρ_p (E v_pi softplus_β(n_p·d_i) + k_amb) / s`` the pixel's normalised luminance under
  light i (the smooth model of :mod:`optlight.scene.luminance` before its clip), so the weight falls
  to 0 where the pixel saturates (level ``ℓ``, width ``τ``). ``ε`` keeps pixels lit by fewer than
  three lights finite (their trace is then about ``1/ε``). The lights are taken as distant
  (directional model; for a point light ``d_i`` is the direction from O, the far-field
  approximation). Vectorised over pixels: ``C = N_S Dᵀ`` (P×N), ``W`` (P×N), the six entries
  ``m_ab = W (D_a ∘ D_b)`` (P×1) and the trace of the inverse in closed form,
  ``tr(M⁻¹) = (cof_00 + cof_11 + cof_22) / det M``.
- :class:`RieszEnergy`: even coverage for RTI, the mean over pairs of ``|d_i − d_j|^{−s}``. For
  ``s > 2`` (hypersingular on the 2-sphere) minimal-energy points are asymptotically uniformly
  distributed on the set (Hardin & Saff, "Discretizing manifolds via minimum energy points",
  Notices AMS 51(10), 2004), so the default is ``s = 4``; :func:`coverage` reports the max-min
  separation and the covering radius of a set.
- :class:`ImageSetTerm`: an image objective (:class:`optlight.objectives.Objective`) applied to
  each light and averaged, ``(1/N) Σ_i J(a(d_i), v_i)``.
- :class:`SetCost`: ``Σ_k w_k · term_k``, itself a set term.

Design. :class:`LightSetDesigner` builds the NLP ``min_x cost(D(x); p)`` s.t. the cap bounds and an
optional extra inequality ``allowed(D) ≤ 0`` (the hook for the view-excluded region and reach) once;
:func:`design_light_set` solves it from several random starts (uniform on the cap's area) and keeps
the best. :func:`design_ring` optimises the slant of an N-light ring, the classical baseline.

Grids. :func:`yale_b_grid` is the Extended Yale B list of 64 flash directions (package data);
:func:`read_grid_file` reads another; :func:`map_grid` maps each grid direction to the nearest
allowed light (a callable or a boolean mask over candidate directions), reporting every replacement.

Angles are radians in code, degrees only in files and reports.
"""

from __future__ import annotations

import csv
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal, Protocol

import casadi as ca
import numpy as np
from numpy.typing import ArrayLike, NDArray

from optlight.errors import OptlightError, ProblemError, UnreachableError
from optlight.geometry import LightSphere, direction_in_sphere_frame
from optlight.planning.nlp import ipopt_options, run
from optlight.scene.luminance import softplus
from optlight.spec import LightSpec, SolverSpec

if TYPE_CHECKING:
    from optlight.objectives import Objective
    from optlight.scene import Scene
    from optlight.spec import Problem

Array = NDArray[np.float64]
Visibility = Callable[[Array], Array]
#: An extra inequality ``allowed(D) ≤ 0`` (elementwise) on the N×3 MX of directions.
AllowedHook = Callable[[ca.MX], ca.MX]

#: Largest number of solves per start: the first with the parameters (visibility masks) at the
#: start, then one more each time the parameters at the solution differ from those solved with.
PARAMETER_ROUNDS = 3
#: Default ε of the per-pixel regulariser M + εI (squared unit lights).
DEFAULT_REGULARIZATION = 1e-2
#: Default Riesz exponent s (hypersingular on the 2-sphere: s > 2).
DEFAULT_RIESZ_EXPONENT = 4.0
#: Slant (rad) of the classical photometric-stereo ring, arccos(1/√3) = 54.7356°.
CLASSICAL_SLANT = math.acos(1.0 / math.sqrt(3.0))
#: Solver settings when none are given: a set has 2N variables on a flat landscape (the Riesz energy
#: of 48 lights needed ~400 L-BFGS iterations to IPOPT's acceptable level, more than [solver]'s 300).
DESIGN_SOLVER = SolverSpec(max_iter=1000)
#: Zeniths of the slant sweep that seeds :func:`design_ring`.
RING_SWEEP = 37


# --------------------------------------------------------------------------------------------
# The cap and directions
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Cap:
    """The allowed zenith range [``zenith_min``, ``zenith_max``] (rad) on the light sphere."""

    zenith_min: float
    zenith_max: float

    def __post_init__(self) -> None:
        if not 0.0 <= self.zenith_min < self.zenith_max <= math.pi:
            raise OptlightError(
                f"a cap needs 0 ≤ zenith_min < zenith_max ≤ π, got {self.zenith_min}, {self.zenith_max}"
            )

    @classmethod
    def from_sphere(cls, sphere: LightSphere) -> Cap:
        """The cap of a light sphere (its ``zenith_min``, ``zenith_max``)."""
        return cls(float(sphere.zenith_min), float(sphere.zenith_max))

    def contains(self, directions: ArrayLike, tol: float = 1e-9) -> NDArray[np.bool_]:
        """Whether each unit direction (..., 3), sphere frame, lies on the cap (zenith within ``tol``)."""
        zenith, _ = angles_of(directions)
        return (zenith >= self.zenith_min - tol) & (zenith <= self.zenith_max + tol)

    def lattice(self, count: int) -> Array:
        """``count`` directions (count, 3) spread evenly over the cap's area: a Fibonacci lattice,
        cos θ uniform on [cos θ_max, cos θ_min] and azimuths stepping by the golden angle."""
        k = np.arange(count) + 0.5
        z = math.cos(self.zenith_min) - k / count * (math.cos(self.zenith_min) - math.cos(self.zenith_max))
        azimuth = np.mod(k * math.pi * (3.0 - math.sqrt(5.0)), 2 * math.pi)
        return direction_in_sphere_frame(np.arccos(z), azimuth)

    def random(self, count: int, rng: np.random.Generator) -> Array:
        """``count`` directions (count, 3) drawn uniformly on the cap's area."""
        z = rng.uniform(math.cos(self.zenith_max), math.cos(self.zenith_min), count)
        return direction_in_sphere_frame(np.arccos(z), rng.uniform(0.0, 2 * math.pi, count))

    def area_count(self, spacing: float) -> int:
        """How many lattice points give neighbours about ``spacing`` (rad) apart: area / spacing²."""
        area = 2 * math.pi * (math.cos(self.zenith_min) - math.cos(self.zenith_max))
        return max(1, math.ceil(area / spacing**2))


def angles_of(directions: ArrayLike) -> tuple[Array, Array]:
    """Zenith θ ∈ [0, π] and azimuth φ ∈ [0, 2π) of directions (..., 3) in the sphere frame."""
    d = np.asarray(directions, float)
    zenith = np.arctan2(np.hypot(d[..., 0], d[..., 1]), d[..., 2])
    return zenith, np.mod(np.arctan2(d[..., 1], d[..., 0]), 2 * math.pi)


def casadi_directions(x: ca.MX) -> ca.MX:
    """The N×3 MX of directions from ``x = (θ_1 … θ_N, φ_1 … φ_N)`` (2N×1)."""
    n = x.size1() // 2
    zenith, azimuth = x[:n], x[n:]
    return ca.horzcat(ca.sin(zenith) * ca.cos(azimuth), ca.sin(zenith) * ca.sin(azimuth), ca.cos(zenith))


def ring_directions(n: int, slant: float, phase: float = 0.0) -> Array:
    """N lights (n, 3) at zenith ``slant`` (rad), azimuths ``phase + 2πi/n``."""
    return direction_in_sphere_frame(np.full(n, slant), phase + 2 * math.pi * np.arange(n) / n)


def min_separation(directions: ArrayLike) -> float:
    """The smallest angle (rad) between two of the directions (N, 3), N ≥ 2."""
    d = np.asarray(directions, float)
    gram = d @ d.T
    np.fill_diagonal(gram, -1.0)
    return float(np.arccos(np.clip(gram.max(), -1.0, 1.0)))


def covering_radius(directions: ArrayLike, cap: Cap, samples: int = 20_000) -> float:
    """The largest angle (rad) from a point of the cap (a lattice of ``samples`` points) to its
    nearest light: every point of the cap is within this angle of a light."""
    gram = cap.lattice(samples) @ np.asarray(directions, float).T
    return float(np.arccos(np.clip(gram.max(axis=1).min(), -1.0, 1.0)))


def coverage(directions: ArrayLike, cap: Cap) -> dict[str, float]:
    """RTI coverage report (degrees): ``min_separation_deg`` (max-min separation of the set) and
    ``covering_radius_deg`` (:func:`covering_radius`)."""
    return {
        "min_separation_deg": math.degrees(min_separation(directions)),
        "covering_radius_deg": math.degrees(covering_radius(directions, cap)),
    }


# --------------------------------------------------------------------------------------------
# Small shared formulas: the same code runs on NumPy arrays and on CasADi MX
# --------------------------------------------------------------------------------------------


def _sigmoid_np(x: Array) -> Array:
    return 0.5 * (1.0 + np.tanh(0.5 * x))


def _sigmoid_ca(x: ca.MX) -> ca.MX:
    return 0.5 * (1.0 + ca.tanh(0.5 * x))


def _softplus_np(x: Array, beta: float) -> Array:
    """softplus_β in the overflow-free form of :func:`optlight.scene.luminance.softplus`."""
    return np.maximum(x, 0.0) + np.log1p(np.exp(-beta * np.abs(x))) / beta


def _trace_of_inverse(m00: Any, m11: Any, m22: Any, m01: Any, m02: Any, m12: Any) -> Any:
    """tr(M⁻¹) of symmetric 3×3 matrices given by their entries (arrays or MX columns, elementwise):
    the diagonal cofactors over the determinant."""
    c00 = m11 * m22 - m12 * m12
    c11 = m00 * m22 - m02 * m02
    c22 = m00 * m11 - m01 * m01
    det = m00 * c00 - m01 * (m01 * m22 - m02 * m12) + m02 * (m01 * m12 - m11 * m02)
    return (c00 + c11 + c22) / det


_PAIRS = ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2))


# --------------------------------------------------------------------------------------------
# Set terms
# --------------------------------------------------------------------------------------------


class SetTerm(Protocol):
    """A scalar of a light set: the same number from NumPy and from CasADi for the same parameters."""

    def parameter_size(self, n: int) -> int:
        """Length of the parameter vector for N lights (0 when the term has none)."""
        ...

    def parameters(self, directions: Array) -> Array:
        """The parameters (held fixed during a solve) at directions (N, 3); shape (parameter_size,)."""
        ...

    def numpy(self, directions: Array, parameters: Array | None = None) -> float:
        """Value at directions (N, 3); ``parameters`` None computes them at ``directions``."""
        ...

    def casadi(self, directions: ca.MX, parameters: ca.MX) -> ca.MX:
        """Value for the N×3 MX ``directions`` and the MX ``parameters``, a scalar MX."""
        ...


class _NoParameters:
    """Mixin of the terms that need no parameters."""

    def parameter_size(self, n: int) -> int:
        return 0

    def parameters(self, directions: Array) -> Array:
        return np.zeros(0)


@dataclass(frozen=True)
class UnshadowedTrace(_NoParameters):
    """``tr((DᵀD)⁻¹)``: distant unit lights that all light the point (no shadow, no saturation)."""

    def numpy(self, directions: Array, parameters: Array | None = None) -> float:
        m = np.asarray(directions, float).T @ np.asarray(directions, float)
        return float(_trace_of_inverse(*(m[a, b] for a, b in _PAIRS)))

    def casadi(self, directions: ca.MX, parameters: ca.MX) -> ca.MX:
        m = ca.mtimes(directions.T, directions)
        return _trace_of_inverse(*(m[a, b] for a, b in _PAIRS))


@dataclass(frozen=True, eq=False)
class PhotometricStereoTerm:
    """The per-pixel expected normal error ``(1/P) Σ_p tr((D_pᵀ W_p D_p + εI)⁻¹)`` (module docstring).

    ``normals`` (P, 3): unit G-buffer normals in the sphere frame. ``albedo`` (P,). ``light``: gain,
    power, ambient, saturation and β of the image model. ``visibility``: directions (N, 3) -> cast-
    shadow mask (P, N) in {0, 1}, or None for no cast shadows (the term then has no parameters).
    ``regularization``: ε. ``saturation_level`` ℓ and ``softness`` τ: normalised luminance where a
    pixel counts as saturated, and the width of that sigmoid."""

    normals: Array
    albedo: Array
    light: LightSpec
    visibility: Visibility | None = None
    regularization: float = DEFAULT_REGULARIZATION
    saturation_level: float = 0.98
    softness: float = 0.01

    @classmethod
    def from_scene(cls, scene: Scene, **options: Any) -> PhotometricStereoTerm:
        """The term on a scene's object pixels; cast shadows from its shadow rays when
        ``light.cast_shadows`` (the mask of light i from the light at ``a(d_i)``)."""
        sphere = scene.sphere
        visibility = None
        if scene.light.cast_shadows:

            def visibility(directions: Array) -> Array:
                positions = sphere.center + sphere.radius * np.asarray(directions, float) @ sphere.rotation.T
                return np.column_stack([scene.visibility(a) for a in positions])

        return cls(
            normals=scene.gbuffer.normals @ sphere.rotation,
            albedo=scene.gbuffer.albedo,
            light=scene.light,
            visibility=visibility,
            **options,
        )

    @property
    def pixels(self) -> int:
        return int(self.albedo.size)

    def parameter_size(self, n: int) -> int:
        return 0 if self.visibility is None else self.pixels * n

    def parameters(self, directions: Array) -> Array:
        """The visibility mask (P, N) flattened column by column (CasADi's reshape order)."""
        if self.visibility is None:
            return np.zeros(0)
        return np.asarray(self.visibility(np.asarray(directions, float)), float).ravel(order="F")

    def weights(self, directions: Array, parameters: Array | None = None) -> Array:
        """The smooth weights w_pi (P, N) of the module docstring."""
        d = np.asarray(directions, float)
        v = self._mask_np(d, parameters)
        lt, beta = self.light, self.light.softplus_sharpness
        cos = self.normals @ d.T
        u = lt.gain * self.albedo[:, None] * (lt.power * v * _softplus_np(cos, beta) + lt.ambient)
        unsaturated = _sigmoid_np((self.saturation_level - u / lt.saturation) / self.softness)
        return v * _sigmoid_np(beta * cos) * unsaturated

    def per_pixel(self, directions: Array, parameters: Array | None = None) -> Array:
        """tr((D_pᵀ W_p D_p + εI)⁻¹) per pixel, shape (P,)."""
        d = np.asarray(directions, float)
        w = self.weights(d, parameters)
        m = [w @ (d[:, a] * d[:, b]) + (self.regularization if a == b else 0.0) for a, b in _PAIRS]
        return np.asarray(_trace_of_inverse(*m), float)

    def numpy(self, directions: Array, parameters: Array | None = None) -> float:
        return float(self.per_pixel(directions, parameters).mean())

    def casadi(self, directions: ca.MX, parameters: ca.MX) -> ca.MX:
        n = directions.size1()
        lt, beta = self.light, self.light.softplus_sharpness
        cos = ca.mtimes(ca.DM(self.normals), directions.T)
        albedo = ca.DM(np.repeat(self.albedo[:, None], n, axis=1))
        if self.visibility is None:
            lit = lt.power * softplus(cos, beta)
            shadow = _sigmoid_ca(beta * cos)
        else:
            v = ca.reshape(parameters, self.pixels, n)
            lit = lt.power * v * softplus(cos, beta)
            shadow = v * _sigmoid_ca(beta * cos)
        u = lt.gain * albedo * (lit + lt.ambient) / lt.saturation
        w = shadow * _sigmoid_ca((self.saturation_level - u) / self.softness)
        m = [
            ca.mtimes(w, directions[:, a] * directions[:, b]) + (self.regularization if a == b else 0.0)
            for a, b in _PAIRS
        ]
        return ca.sum1(_trace_of_inverse(*m)) / self.pixels

    def _mask_np(self, directions: Array, parameters: Array | None) -> Array | float:
        if self.visibility is None:
            return 1.0
        p = self.parameters(directions) if parameters is None else np.asarray(parameters, float)
        return p.reshape(self.pixels, len(directions), order="F")


@dataclass(frozen=True)
class RieszEnergy(_NoParameters):
    """Riesz s-energy per pair: ``(1/(N(N−1))) Σ_{i≠j} |d_i − d_j|^{−s}`` with
    ``|d_i − d_j|² = 2 − 2 d_i·d_j`` for unit directions; N ≥ 2. Two coincident lights: +inf (the
    NumPy twin, or ~1e30 by rounding; a replacement scores a candidate on another light that way)."""

    exponent: float = DEFAULT_RIESZ_EXPONENT

    def numpy(self, directions: Array, parameters: Array | None = None) -> float:
        d = np.asarray(directions, float)
        n = len(d)
        sq = np.maximum(2.0 - 2.0 * (d @ d.T), 0.0) + np.eye(n)  # 1 on the diagonal: each adds 1, removed below
        with np.errstate(divide="ignore"):
            return float(((sq ** (-0.5 * self.exponent)).sum() - n) / (n * (n - 1)))

    def casadi(self, directions: ca.MX, parameters: ca.MX) -> ca.MX:
        n = directions.size1()
        sq = 2.0 - 2.0 * ca.mtimes(directions, directions.T) + ca.DM.eye(n)
        return (ca.sum1(ca.sum2(sq ** (-0.5 * self.exponent))) - n) / (n * (n - 1))


class ImageSetTerm:
    """An image objective applied to each light and averaged: ``(1/N) Σ_i J(a(d_i), v_i)``.

    ``J`` is ``objective.function`` (the smooth differentiable model) at the light position
    ``a(d) = O + b R_WS d``; the parameters are the cast-shadow masks ``v_i`` (P, N) from the scene's
    shadow rays. The NumPy twin scores the NumPy renderer's (exact, non-smooth) images with the same
    masks, so the two differ by the model's smoothing, as :meth:`Objective.function` and the exact
    cost of a landmark do."""

    def __init__(self, objective: Objective, scene: Scene) -> None:
        self.objective = objective
        self.scene = scene
        self.sphere = scene.sphere

    def positions(self, directions: Array) -> Array:
        """Light positions (N, 3), world frame, m."""
        return (
            self.sphere.center + self.sphere.radius * np.asarray(directions, float) @ self.sphere.rotation.T
        )

    def parameter_size(self, n: int) -> int:
        return self.scene.gbuffer.size * n

    def parameters(self, directions: Array) -> Array:
        masks = [self.scene.visibility(a) for a in self.positions(directions)]
        return np.column_stack(masks).ravel(order="F")

    def numpy(self, directions: Array, parameters: Array | None = None) -> float:
        p = self.parameters(directions) if parameters is None else np.asarray(parameters, float)
        masks = p.reshape(self.scene.gbuffer.size, len(directions), order="F")
        costs = [
            self.objective.numpy(self.scene.pixels(a, masks[:, i]))
            for i, a in enumerate(self.positions(directions))
        ]
        return float(np.mean(costs))

    def casadi(self, directions: ca.MX, parameters: ca.MX) -> ca.MX:
        n = directions.size1()
        size = self.scene.gbuffer.size
        positions = ca.DM(self.sphere.center) + self.sphere.radius * ca.mtimes(
            ca.DM(self.sphere.rotation), directions.T
        )
        f = self.objective.function
        total = ca.MX(0)
        for i in range(n):
            total = total + f(positions[:, i], parameters[i * size : (i + 1) * size])
        return total / n


@dataclass(frozen=True)
class SetCost:
    """``Σ_k w_k · term_k`` over set terms; the parameters are the terms' parameters, concatenated."""

    terms: tuple[tuple[float, SetTerm], ...]

    def __init__(self, terms: Sequence[tuple[float, SetTerm]]) -> None:
        if not terms:
            raise OptlightError("a set cost needs at least one term")
        object.__setattr__(self, "terms", tuple((float(w), t) for w, t in terms))

    def parameter_size(self, n: int) -> int:
        return sum(t.parameter_size(n) for _, t in self.terms)

    def parameters(self, directions: Array) -> Array:
        return np.concatenate([np.zeros(0), *(t.parameters(directions) for _, t in self.terms)])

    def numpy(self, directions: Array, parameters: Array | None = None) -> float:
        d = np.asarray(directions, float)
        p = self.parameters(d) if parameters is None else np.asarray(parameters, float)
        total, start = 0.0, 0
        for w, t in self.terms:
            size = t.parameter_size(len(d))
            total += w * t.numpy(d, p[start : start + size])
            start += size
        return total

    def casadi(self, directions: ca.MX, parameters: ca.MX) -> ca.MX:
        total, start = ca.MX(0), 0
        for w, t in self.terms:
            size = t.parameter_size(directions.size1())
            total = total + w * t.casadi(directions, parameters[start : start + size])
            start += size
        return total


# --------------------------------------------------------------------------------------------
# Design
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class LightSetResult:
    """A designed set: ``directions`` (N, 3) sphere frame, ``zenith`` and ``azimuth`` (N,) rad,
    ``cost`` (NumPy twin, parameters at the solution), IPOPT ``iterations`` (all rounds of the best
    start), its ``status`` and ``success``, and the final cost of every start (``start_costs``)."""

    directions: Array
    zenith: Array
    azimuth: Array
    cost: float
    iterations: int
    status: str
    success: bool
    start_costs: tuple[float, ...] = field(default=())

    @property
    def count(self) -> int:
        return int(len(self.directions))

    def world_directions(self, sphere: LightSphere) -> Array:
        """The directions (N, 3) in the world frame."""
        return self.directions @ sphere.rotation.T


def check_in_cap(directions: ArrayLike, cap: Cap, file: str = "<api>", key: str = "start") -> Array:
    """``directions`` as a unit (N, 3) array on the cap, or :class:`ProblemError` naming ``key``."""
    d = np.asarray(directions, float)
    if d.ndim != 2 or d.shape[1] != 3 or not np.allclose(np.linalg.norm(d, axis=1), 1.0, atol=1e-6):
        raise ProblemError(file, key, "unit light directions, shape (N, 3)", f"shape {d.shape}")
    outside = np.flatnonzero(~cap.contains(d, tol=1e-6))
    if outside.size:
        zenith = math.degrees(float(angles_of(d[outside[0]])[0]))
        raise ProblemError(
            file,
            key,
            f"directions inside the cap (zenith {math.degrees(cap.zenith_min):g}°–"
            f"{math.degrees(cap.zenith_max):g}°)",
            f"direction {outside[0]} at zenith {zenith:.3f}°",
        )
    return d


class LightSetDesigner:
    """The NLP of one set size, built once: ``min_x cost(D(x); p)`` s.t. ``θ_min ≤ θ_i ≤ θ_max``
    and, when given, ``allowed(D(x)) ≤ 0``; ``p`` the objective's parameters."""

    def __init__(
        self,
        objective: SetTerm,
        n: int,
        cap: Cap,
        solver: SolverSpec | None = None,
        allowed: AllowedHook | None = None,
    ) -> None:
        if n < 1:
            raise OptlightError(f"a light set needs at least one light, got {n}")
        self.objective, self.n, self.cap = objective, n, cap
        x = ca.MX.sym("x", 2 * n)
        p = ca.MX.sym("p", objective.parameter_size(n))
        d = casadi_directions(x)
        cost = objective.casadi(d, p)
        nlp: dict[str, ca.MX] = {"x": x, "p": p, "f": cost}
        self.constraints = 0
        if allowed is not None:
            g = ca.vec(allowed(d))
            nlp["g"] = g
            self.constraints = int(g.size1())
        self.nlp = ca.nlpsol("light_set", "ipopt", nlp, ipopt_options(solver or DESIGN_SOLVER))
        #: ``(x, p) -> (cost, ∂cost/∂x)``, for checks against finite differences.
        self.cost_gradient = ca.Function("set_cost", [x, p], [cost, ca.gradient(cost, x)])

    def solve(self, start: ArrayLike) -> LightSetResult:
        """Solve from ``start`` (N, 3) directions on the cap, re-solving while the parameters at the
        solution differ from those solved with (at most :data:`PARAMETER_ROUNDS` solves)."""
        d = check_in_cap(start, self.cap)
        if len(d) != self.n:
            raise OptlightError(f"this designer places {self.n} lights, the start has {len(d)}")
        zenith, azimuth = angles_of(d)
        x = np.r_[zenith, azimuth]
        p = self.objective.parameters(d)
        iterations, status, success = 0, "", False
        for _ in range(PARAMETER_ROUNDS):
            solved = run(
                self.nlp,
                {
                    "x0": x,
                    "p": p,
                    "lbx": np.r_[np.full(self.n, self.cap.zenith_min), np.full(self.n, -np.inf)],
                    "ubx": np.r_[np.full(self.n, self.cap.zenith_max), np.full(self.n, np.inf)],
                    "lbg": -np.inf,
                    "ubg": 0.0,
                },
            )
            iterations += solved.iterations
            status, success, x = solved.status, solved.success, solved.x
            d = direction_in_sphere_frame(x[: self.n], x[self.n :])
            p_new = self.objective.parameters(d)
            if np.array_equal(p_new, p):
                break
            p = p_new
        zenith, azimuth = angles_of(d)
        return LightSetResult(d, zenith, azimuth, self.objective.numpy(d, p), iterations, status, success)


def design_light_set(
    objective: SetTerm,
    n: int,
    cap: Cap,
    start: ArrayLike | None = None,
    *,
    starts: int = 8,
    seed: int = 0,
    allowed: AllowedHook | None = None,
    solver: SolverSpec | None = None,
    designer: LightSetDesigner | None = None,
    start_pool: ArrayLike | None = None,
) -> LightSetResult:
    """The best of several solves of the set NLP (:class:`LightSetDesigner`, built once).

    Starts: ``start`` (N, 3) directions on the cap when given (then it is the only start), else
    ``starts`` sets drawn with ``np.random.default_rng(seed)``: N distinct directions of
    ``start_pool`` (P ≥ N, 3; on the cap) each when given — where ``allowed`` holds, so that IPOPT
    starts feasible (from uniform starts on the cap it reported a thin band of reachable lights
    infeasible) — else uniformly on the cap's area. A ``designer`` built before for the same
    objective, N and cap is reused. Returns the start with the lowest final cost; ``start_costs``
    lists every start's."""
    if designer is None:
        designer = LightSetDesigner(objective, n, cap, solver, allowed)
    elif designer.n != n or designer.cap != cap or designer.objective is not objective:
        raise OptlightError("the designer was built for another objective, light count or cap")
    rng = np.random.default_rng(seed)
    if start is not None:
        candidates = [check_in_cap(start, cap)]
    elif start_pool is not None:
        pool = check_in_cap(start_pool, cap)
        if len(pool) < n:
            raise OptlightError(f"{len(pool)} start directions for a set of {n} lights")
        candidates = [pool[rng.choice(len(pool), n, replace=False)] for _ in range(max(1, starts))]
    else:
        candidates = [cap.random(n, rng) for _ in range(max(1, starts))]
    results = [designer.solve(s) for s in candidates]
    best = min(results, key=lambda r: (not r.success, r.cost))
    return _with_start_costs(best, tuple(r.cost for r in results))


def _with_start_costs(result: LightSetResult, costs: tuple[float, ...]) -> LightSetResult:
    return LightSetResult(
        result.directions,
        result.zenith,
        result.azimuth,
        result.cost,
        result.iterations,
        result.status,
        result.success,
        costs,
    )


def design_ring(
    objective: SetTerm, n: int, cap: Cap, phase: float = 0.0, solver: SolverSpec | None = None
) -> LightSetResult:
    """The best ring of N lights (azimuths ``phase + 2πi/N``): the slant is swept over the cap
    (:data:`RING_SWEEP` zeniths, NumPy twin with parameters at each), then refined by IPOPT from the
    best sample (parameters re-computed between solves as in :meth:`LightSetDesigner.solve`)."""
    slants = np.linspace(cap.zenith_min, cap.zenith_max, RING_SWEEP)
    with np.errstate(divide="ignore", invalid="ignore"):  # slant 0 puts every light in one place
        sweep = np.array([objective.numpy(ring_directions(n, s, phase)) for s in slants])
    sweep[~np.isfinite(sweep)] = np.inf
    slant = ca.MX.sym("slant")
    p = ca.MX.sym("p", objective.parameter_size(n))
    azimuths = ca.DM(phase + 2 * math.pi * np.arange(n) / n)
    d = ca.horzcat(
        ca.sin(slant) * ca.cos(azimuths), ca.sin(slant) * ca.sin(azimuths), ca.cos(slant) * ca.DM.ones(n)
    )
    nlp = ca.nlpsol(
        "light_ring",
        "ipopt",
        {"x": slant, "p": p, "f": objective.casadi(d, p)},
        ipopt_options(solver or DESIGN_SOLVER),
    )
    s = float(slants[int(np.argmin(sweep))])
    params = objective.parameters(ring_directions(n, s, phase))
    iterations, status, success = 0, "", False
    for _ in range(PARAMETER_ROUNDS):
        solved = run(nlp, {"x0": s, "p": params, "lbx": cap.zenith_min, "ubx": cap.zenith_max})
        iterations += solved.iterations
        status, success, s = solved.status, solved.success, float(solved.x[0])
        new = objective.parameters(ring_directions(n, s, phase))
        if np.array_equal(new, params):
            break
        params = new
    directions = ring_directions(n, s, phase)
    zenith, azimuth = angles_of(directions)
    cost = objective.numpy(directions, params)
    return LightSetResult(directions, zenith, azimuth, cost, iterations, status, success, (cost,))


# --------------------------------------------------------------------------------------------
# Grids (face databases)
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Grid:
    """A given list of light directions: ``names`` and ``directions`` (K, 3), sphere frame."""

    names: tuple[str, ...]
    directions: Array


def camera_axis_direction(azimuth: ArrayLike, elevation: ArrayLike) -> Array:
    """Unit directions (..., 3), sphere frame, of lights given by azimuth A and elevation E (rad)
    relative to the camera axis, the Yale B convention: E > 0 above the horizon, A > 0 to the
    subject's right, which faces the camera and so is the image's left (−x_S):
    ``(−sin A cos E, sin E, cos A cos E)`` with x_S right and y_S up in the image, z_S towards the
    camera. (The Yale B list is mirror-symmetric in A, so the set is the same with either sign.)"""
    a, e = np.broadcast_arrays(np.asarray(azimuth, float), np.asarray(elevation, float))
    return np.stack([-np.sin(a) * np.cos(e), np.sin(e), np.cos(a) * np.cos(e)], axis=-1)


def grid_from_degrees(pairs: Sequence[Sequence[float]], names: Sequence[str] | None = None) -> Grid:
    """A grid from (azimuth_deg, elevation_deg) pairs relative to the camera axis."""
    a = np.asarray(pairs, float).reshape(-1, 2)
    labels = tuple(names) if names is not None else tuple(f"A{x:+04.0f}E{y:+03.0f}" for x, y in a)
    return Grid(labels, camera_axis_direction(np.deg2rad(a[:, 0]), np.deg2rad(a[:, 1])))


def read_grid_file(path: str | Path, file: str = "<api>", key: str = "lightset.grid_file") -> Grid:
    """A grid from a CSV file: ``#`` comment lines, a header with the columns ``azimuth_deg`` and
    ``elevation_deg`` (relative to the camera axis, :func:`camera_axis_direction`) and optionally
    ``name``, then one light per row. Errors name ``file`` and ``key`` and the offending line."""
    path = Path(path)
    expected = "a CSV grid with columns azimuth_deg, elevation_deg [, name]"
    try:
        text = path.read_text()
    except (OSError, UnicodeDecodeError) as e:
        raise ProblemError(file, key, expected, f"{path} ({e})") from None
    lines = [
        (i + 1, s) for i, s in enumerate(text.splitlines()) if s.strip() and not s.lstrip().startswith("#")
    ]
    if not lines:
        raise ProblemError(file, key, expected, f"{path} (no rows)")
    header = [h.strip() for h in next(csv.reader([lines[0][1]]))]
    if "azimuth_deg" not in header or "elevation_deg" not in header:
        raise ProblemError(file, key, expected, f"{path} line {lines[0][0]} header {lines[0][1]!r}")
    ia, ie = header.index("azimuth_deg"), header.index("elevation_deg")
    iname = header.index("name") if "name" in header else None
    pairs, names = [], []
    for number, line in lines[1:]:
        row = [c.strip() for c in next(csv.reader([line]))]
        try:
            if len(row) != len(header):
                raise ValueError
            azimuth, elevation = float(row[ia]), float(row[ie])
            if not (math.isfinite(azimuth) and math.isfinite(elevation) and -90.0 <= elevation <= 90.0):
                raise ValueError
        except ValueError:
            raise ProblemError(
                file,
                key,
                f"{len(header)} fields per row, finite angles, elevation in [−90, 90]",
                f"{path.name} line {number}: {line.strip()!r}",
            ) from None
        pairs.append((azimuth, elevation))
        names.append(row[iname] if iname is not None else f"A{azimuth:+04.0f}E{elevation:+03.0f}")
    if not pairs:
        raise ProblemError(file, key, expected, f"{path} (a header but no rows)")
    return grid_from_degrees(pairs, names)


def yale_b_grid() -> Grid:
    """The 64 flash directions of the (Extended) Yale Face Database B (``optlight/data/yale_b_64.csv``;
    its header cites the source), as :func:`read_grid_file` reads them."""
    with resources.as_file(resources.files("optlight") / "data" / "yale_b_64.csv") as path:
        return read_grid_file(path, file=str(path), key="")


@dataclass(frozen=True)
class GridMapping:
    """Requested and achieved lights of a grid: ``requested`` and ``achieved`` (K, 3) sphere frame,
    ``moved`` (K,) the angle between them (rad), ``replaced`` (K,) where they differ, ``names``."""

    names: tuple[str, ...]
    requested: Array
    achieved: Array
    moved: Array
    replaced: NDArray[np.bool_]

    @property
    def replaced_count(self) -> int:
        return int(self.replaced.sum())

    def report(self) -> dict[str, Any]:
        """Requested vs achieved in a JSON-friendly summary (degrees)."""
        return {
            "requested": len(self.names),
            "achieved_exactly": len(self.names) - self.replaced_count,
            "replaced": [
                {"name": n, "moved_deg": math.degrees(float(m))}
                for n, m, r in zip(self.names, self.moved, self.replaced, strict=True)
                if r
            ],
            "max_moved_deg": math.degrees(float(self.moved.max(initial=0.0))),
        }


def map_grid(
    grid: Grid,
    cap: Cap,
    allowed: Callable[[Array], NDArray[np.bool_]] | NDArray[np.bool_] | None = None,
    candidates: ArrayLike | None = None,
    *,
    spacing: float = math.radians(2.0),
    distinct: bool = True,
    outside_cap: Literal["replace", "error"] = "replace",
    file: str = "<api>",
    key: str = "lightset.grid",
) -> GridMapping:
    """Each grid direction mapped to the nearest allowed light.

    ``allowed``: a callable ``directions (M, 3) -> bool (M,)`` (the lead's reachable-and-clear
    predicate), or a boolean mask over ``candidates`` (M, 3), or None (the whole cap). Candidates:
    ``candidates`` when given, else the grid's own directions plus a lattice of the cap about
    ``spacing`` (rad) apart; only those on the cap and allowed are used. ``distinct``: no two grid
    lights share a candidate (an assignment minimising Σ moved², :func:`scipy.optimize.linear_sum_assignment`);
    otherwise each takes its nearest. ``outside_cap = "error"`` refuses grid directions off the cap
    (a :class:`ProblemError` naming ``key``) instead of replacing them.
    Raises :class:`UnreachableError` when fewer candidates are allowed than the grid needs."""
    from scipy.optimize import linear_sum_assignment

    requested = np.asarray(grid.directions, float)
    if outside_cap == "error":
        outside = np.flatnonzero(~cap.contains(requested, tol=1e-9))
        if outside.size:
            zenith = math.degrees(float(angles_of(requested[outside[0]])[0]))
            raise ProblemError(
                file,
                key,
                f"grid directions inside the cap (zenith ≤ {math.degrees(cap.zenith_max):g}°)",
                f"{grid.names[outside[0]]} at zenith {zenith:.1f}°",
            )
    if isinstance(allowed, np.ndarray):
        if candidates is None:
            raise OptlightError("an allowed mask needs the candidates it is over")
        pool = np.asarray(candidates, float)
        ok = np.asarray(allowed, bool)
        if ok.shape != (len(pool),):
            raise OptlightError(f"allowed mask of shape {ok.shape} for {len(pool)} candidates")
    else:
        pool = (
            np.asarray(candidates, float)
            if candidates is not None
            else np.vstack([requested, cap.lattice(cap.area_count(spacing))])
        )
        ok = np.ones(len(pool), bool) if allowed is None else np.asarray(allowed(pool), bool)
    ok = ok & cap.contains(pool)
    usable = pool[ok]
    need = len(requested) if distinct else 1
    if len(usable) < need:
        raise UnreachableError(
            f"{len(usable)} allowed light directions for a grid of {len(requested)}: "
            "widen the cap or the allowed region"
        )
    # atan2(|a × b|, a·b): accurate for small angles too, where arccos(a·b) is off by ~1e-8 rad
    cross = np.linalg.norm(np.cross(requested[:, None, :], usable[None, :, :]), axis=2)
    angle = np.arctan2(cross, requested @ usable.T)
    pick = angle.argmin(axis=1)
    if distinct:
        # grid lights that are allowed as they are keep their place; the rest share what is left
        exact = angle[np.arange(len(requested)), pick] <= 1e-12
        rest = np.flatnonzero(~exact)
        free = np.setdiff1d(np.arange(len(usable)), pick[exact])
        if len(free) < len(rest) or len(set(pick[exact])) < exact.sum():
            raise UnreachableError(
                f"{len(usable)} allowed light directions cannot hold a grid of {len(requested)} distinct lights"
            )
        rows, cols = linear_sum_assignment(angle[np.ix_(rest, free)] ** 2)
        pick[rest[rows]] = free[cols]
    achieved = usable[pick]
    moved = angle[np.arange(len(requested)), pick]
    return GridMapping(grid.names, requested, achieved, moved, moved > 1e-12)


# --------------------------------------------------------------------------------------------
# From a problem file
# --------------------------------------------------------------------------------------------


def set_cost_from_problem(problem: Problem, scene: Scene, objective: Objective | None = None) -> SetCost:
    """The set cost of a problem's ``[lightset]``: ``photometric_stereo`` (the per-pixel term on
    ``scene``) or ``rti`` (Riesz energy), plus ``image_weight`` × the image objective averaged over
    the lights when that weight is positive (``objective``, the problem's ``[objective]``)."""
    spec = problem.lightset
    file = str(problem.source) if problem.source else "<inline>"
    terms: list[tuple[float, SetTerm]] = []
    if spec.kind == "photometric_stereo":
        terms.append(
            (
                1.0,
                PhotometricStereoTerm.from_scene(
                    scene,
                    regularization=spec.regularization,
                    saturation_level=spec.saturation_level,
                    softness=spec.softness,
                ),
            )
        )
    elif spec.kind == "rti":
        terms.append((1.0, RieszEnergy(spec.riesz_exponent)))
    else:
        raise ProblemError(
            file, "lightset.kind", "a designed set ('photometric_stereo' or 'rti') for a set cost", spec.kind
        )
    if spec.image_weight > 0:
        if objective is None:
            raise OptlightError("lightset.image_weight > 0 needs the problem's image objective")
        terms.append((spec.image_weight, ImageSetTerm(objective, scene)))
    return SetCost(terms)


def grid_from_problem(problem: Problem) -> Grid:
    """The grid of a problem's ``[lightset]`` (kind = grid): ``grid_deg`` pairs, ``grid_file``, or the
    Yale B 64 directions when neither is set."""
    spec = problem.lightset
    file = str(problem.source) if problem.source else "<inline>"
    if spec.grid_deg is not None:
        return _distinct_grid(grid_from_degrees(spec.grid_deg), file, "lightset.grid_deg", "grid_deg[{}]", 0)
    if spec.grid_file is not None:
        key = "lightset.grid_file"
        grid = read_grid_file(problem.resolve(spec.grid_file), file, key)
        return _distinct_grid(grid, file, key, f"{Path(spec.grid_file).name} data row {{}}", 1)
    return yale_b_grid()


#: Grid directions closer than this (rad) are the same light: one capture cannot stand for two.
SAME_DIRECTION_RAD = 1e-9


def _distinct_grid(grid: Grid, file: str, key: str, entry: str, first: int) -> Grid:
    """``grid`` when no two of its directions are the same light (within :data:`SAME_DIRECTION_RAD`);
    else a :class:`ProblemError` naming ``file``, ``key`` and the first two such entries (``entry``
    formatted with their index counted from ``first``)."""
    d = grid.directions
    cross = np.linalg.norm(np.cross(d[:, None, :], d[None, :, :]), axis=2)
    angle = np.arctan2(cross, d @ d.T)
    same = np.argwhere(np.triu(angle <= SAME_DIRECTION_RAD, k=1))
    if same.size:
        i, j = same[0]
        raise ProblemError(
            file,
            key,
            "distinct light directions (a grid light is one capture)",
            f"{entry.format(i + first)} ({grid.names[i]}) and {entry.format(j + first)} ({grid.names[j]}) "
            "are the same direction",
        )
    return grid
