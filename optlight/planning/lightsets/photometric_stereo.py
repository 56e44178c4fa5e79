"""The photometric-stereo set terms (docs/design.md §10): :class:`UnshadowedTrace`,
``tr((DᵀD)⁻¹)``, and the per-pixel :class:`PhotometricStereoTerm`,
``(1/P) Σ_p tr((D_pᵀ W_p D_p + εI)⁻¹)`` with the smooth weights of the attached shadow, the cast
shadow and saturation (the formulas are in :mod:`optlight.planning.lightsets`). The small formulas
here run on NumPy arrays and on CasADi MX alike.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import casadi as ca
import numpy as np

from optlight.planning.lightsets.cost import NoParameters
from optlight.planning.lightsets.directions import Array
from optlight.scene.luminance import softplus
from optlight.spec import LightSpec

if TYPE_CHECKING:
    from optlight.scene import Scene


Visibility = Callable[[Array], Array]


#: Default ε of the per-pixel regulariser M + εI (squared unit lights).
DEFAULT_REGULARIZATION = 1e-2


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


@dataclass(frozen=True)
class UnshadowedTrace(NoParameters):
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
