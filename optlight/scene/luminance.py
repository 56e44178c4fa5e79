"""Differentiable luminance: the model of docs/design.md §4 as a CasADi Function (a, v) -> I.

One MX graph per scene, whatever the number P of pixels: the G-buffer enters as constant
matrices — normals N (P×3), points X (P×3), albedo ρ (P×1) — so every operation is a matrix
product or an element-wise operation on P×1 vectors, never a per-pixel scalar graph.

- directional: c = N (a − O)/b, f = 1;
- point: with r² = |a|² − 2 X a + |X|²_row (|a − p_i|², expanded so that a appears only in
  products with constants) and k = rowsum(N ∘ X): c = (N a − k)/√r², f = b²/r²;
- I = clip_s(g ρ ∘ (E v ∘ max₊(c) ∘ f + k_amb)).

Cast shadows enter through v (P×1, 0/1), a *fixed* mask the caller recomputes between solves
(:meth:`optlight.scene.Scene.visibility`); its dependence on a is not differentiated.

``smooth=True``: max₊(x) = softplus_β(x) = log(1 + e^{βx})/β, computed as
max(x, 0) + log(1 + e^{−β|x|})/β (never overflows; smooth, its derivative is the logistic
σ(βx)), with β = ``softplus_sharpness``; it exceeds max(x, 0) by at most log(2)/β, at x = 0.
clip_s(x) = s − softplus_γ(s − x) with γ = ``clip_sharpness``: a smooth min(x, s). The lower clip
at 0 is left out on purpose: the noise-free model value is ≥ g ρ k_amb ≥ 0, so the hard lower clip
is inactive, while a smooth one would add a bias of ~e^{−γx}/γ to exactly the dark pixels; the
smooth value stays ≥ −log(1 + e^{−γs})/γ (−1.5e−28 at the defaults).
``smooth=False``: max₊ = fmax(x, 0), clip_s = fmin(fmax(x, 0), s), the NumPy renderer's model.
"""

from __future__ import annotations

import casadi as ca
import numpy as np
from numpy.typing import ArrayLike

from optlight.scene.gbuffer import GBuffer
from optlight.spec import LightSpec


def softplus(x: ca.MX, beta: float) -> ca.MX:
    """softplus_β(x) = log(1 + e^{βx})/β in the overflow-free form max(x, 0) + log(1 + e^{−β|x|})/β."""
    return ca.fmax(x, 0) + ca.log1p(ca.exp(-beta * ca.fabs(x))) / beta


def luminance_function(
    gbuffer: GBuffer,
    light: LightSpec,
    center: ArrayLike,
    radius: float,
    smooth: bool = True,
) -> ca.Function:
    """The CasADi Function ``luminance``: inputs ``a`` (3×1, light position, world, m) and ``v``
    (P×1 visibility, 0/1), output ``I`` (P×1 pixel values), for the G-buffer's pixels in order.

    ``center``, ``radius``: the light sphere's O (m) and b (m). See the module docstring for the
    model and the smooth forms.
    """
    normals = ca.DM(gbuffer.normals)
    albedo = ca.DM(gbuffer.albedo)
    a = ca.MX.sym("a", 3)
    v = ca.MX.sym("v", gbuffer.size)
    if light.model == "directional":
        cos = ca.mtimes(normals, (a - ca.DM(np.asarray(center, float))) / radius)
        falloff: ca.MX | float = 1.0
    else:
        points = ca.DM(gbuffer.points)
        n_dot_p = ca.DM(np.einsum("ij,ij->i", gbuffer.normals, gbuffer.points))
        p_sq = ca.DM(np.einsum("ij,ij->i", gbuffer.points, gbuffer.points))
        r2 = ca.dot(a, a) - 2 * ca.mtimes(points, a) + p_sq
        cos = (ca.mtimes(normals, a) - n_dot_p) / ca.sqrt(r2)
        falloff = radius**2 / r2
    if smooth:
        lit = softplus(cos, light.softplus_sharpness)
    else:
        lit = ca.fmax(cos, 0)
    raw = light.gain * albedo * (light.power * v * lit * falloff + light.ambient)
    if smooth:
        image = light.saturation - softplus(light.saturation - raw, light.clip_sharpness)
    else:
        image = ca.fmin(ca.fmax(raw, 0), light.saturation)
    return ca.Function("luminance", [a, v], [image], ["a", "v"], ["I"])
