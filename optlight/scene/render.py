"""NumPy renderer: the Lambertian luminance model of docs/design.md §4, evaluated exactly.

For G-buffer pixel i with point p_i (m), unit normal n_i, albedo ρ_i and cast-shadow visibility
v_i ∈ {0, 1}, and a light at a (m) on the sphere of centre O and radius b:

- directional: l = (a − O)/b, falloff f_i = 1;
- point: l_i = (a − p_i)/|a − p_i|, falloff f_i = (b/|a − p_i|)² (1 at the sphere radius);

    I_i = clip(g·ρ_i·(E·v_i·max(0, n_i·l_i)·f_i + k_amb) [+ η_i], 0, s)

with gain g, light power E, ambient k_amb, saturation s (``LightSpec``) and, only when asked, sensor
noise η_i ~ N(0, σ²), σ = ``noise_std``, added before the clip. Pixel values are in the camera's
linear units (1 = saturation at the default settings).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from optlight.scene.gbuffer import GBuffer
from optlight.spec import LightSpec

Array = NDArray[np.float64]


def cosine_and_falloff(
    points: ArrayLike, normals: ArrayLike, light_position: ArrayLike, model: str, center: ArrayLike, radius: float
) -> tuple[Array, Array]:
    """n_i·l_i and the falloff f_i of surface points p_i (N, 3) with unit normals n_i (N, 3) (see the
    module docstring)."""
    a = np.asarray(light_position, float)
    normals = np.asarray(normals, float)
    if model == "directional":
        cos = normals @ ((a - np.asarray(center, float)) / radius)
        return cos, np.ones_like(cos)
    to_light = a - np.asarray(points, float)
    r2 = np.einsum("ij,ij->i", to_light, to_light)
    cos = np.einsum("ij,ij->i", normals, to_light) / np.sqrt(r2)
    return cos, radius**2 / r2


def lambertian(
    points: ArrayLike,
    normals: ArrayLike,
    albedo: ArrayLike,
    light_position: ArrayLike,
    light: LightSpec,
    center: ArrayLike,
    radius: float,
    visibility: ArrayLike = 1.0,
) -> Array:
    """g·ρ_i·(E·v_i·max(0, n_i·l_i)·f_i + k_amb) of surface points, before noise and clip: the one
    place the model of docs/design.md §4 is written (the renderer's pixels, the preview's vertices)."""
    cos, falloff = cosine_and_falloff(points, normals, light_position, light.model, center, radius)
    v = np.asarray(visibility, float)
    return light.gain * np.asarray(albedo, float) * (light.power * v * np.maximum(cos, 0.0) * falloff + light.ambient)


def shade(
    gbuffer: GBuffer,
    light_position: ArrayLike,
    light: LightSpec,
    center: ArrayLike,
    radius: float,
    visibility: ArrayLike,
    noise: bool | np.random.Generator = False,
) -> Array:
    """Pixel values I_i (P,) of the G-buffer pixels lit from ``light_position`` (world, m).

    ``center``, ``radius``: the light sphere's O and b. ``visibility``: v_i (P,). ``noise``: False
    for none; True draws η from ``np.random.default_rng(light.seed)`` afresh on each call (the same
    seed gives the same pattern); a Generator draws the next values from it.
    """
    value = lambertian(
        gbuffer.points, gbuffer.normals, gbuffer.albedo, light_position, light, center, radius, visibility
    )
    if noise is not False and light.noise_std > 0:
        rng = noise if isinstance(noise, np.random.Generator) else np.random.default_rng(light.seed)
        value = value + rng.normal(0.0, light.noise_std, value.shape)
    return np.clip(value, 0.0, light.saturation)


def to_image(gbuffer: GBuffer, pixels: ArrayLike, background: float = 0.0) -> Array:
    """The (H, W) image holding ``pixels`` (P,) at the object pixels and ``background`` elsewhere."""
    h, w = gbuffer.mask.shape
    image = np.full(h * w, float(background))
    image[gbuffer.pixel_index] = np.asarray(pixels, float)
    return image.reshape(h, w)
