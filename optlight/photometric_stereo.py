"""Photometric stereo (docs/design.md §10): normals and albedo from N images under N known distant lights.

Model (Lambertian, distant lights): pixel p under light k has the value

    I_pk = ρ_p e_k (n_p·l_k) + a_p + η_pk,

``l_k`` the unit light direction, ``e_k`` its strength in pixel units (``gain · power`` for the model
camera), ``a_p`` the ambient (the image with the light off, subtracted when given) and ``η`` noise.
Per pixel, only the *usable* lights enter: those where the pixel is neither shadowed,
``(I_pk − a_p)/s > dark_level``, nor saturated, ``I_pk/s < saturation_level`` (``s`` the saturation
value). With ``S`` the usable rows ``e_k l_kᵀ`` and ``b_p = ρ_p n_p``, the least-squares estimate is

    b̂_p = (SᵀS)⁻¹ Sᵀ (I_p − a_p),   ρ̂_p = |b̂_p|,   n̂_p = b̂_p / |b̂_p|,

defined where at least ``min_lights`` (≥ 3) lights are usable and ``SᵀS`` is well conditioned. With
independent noise of standard deviation σ, ``E|b̂_p − b_p|² = σ² tr((SᵀS)⁻¹)`` exactly, so for
unit lights ``E|b̂_p/ρ_p − n_p|² = (σ/(eρ_p))² tr((LᵀL)⁻¹)``, the quantity
:class:`optlight.planning.lightsets.PhotometricStereoTerm` minimises; to first order in σ the unit normal's
error is the part orthogonal to ``n_p``, ``E|n̂_p − n_p|² ≈ (σ/(eρ_p))² tr((I − n nᵀ)(LᵀL)⁻¹)``.

Normals come out in the frame the light directions are given in (world directions give world
normals, comparable with the G-buffer's). Angles in reports are degrees.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from optlight.errors import OptlightError, ProblemError
from optlight.scene.response import linearise

if TYPE_CHECKING:
    from matplotlib.figure import Figure

    from optlight.scene import Scene

Array = NDArray[np.float64]

#: Smallest ratio of the smallest to the largest eigenvalue of SᵀS for a pixel to be solved.
MIN_CONDITION = 1e-6


@dataclass(frozen=True, eq=False)
class NormalRecovery:
    """The result of :func:`recover_normals`, all (H, W) images.

    ``normals`` (H, W, 3): unit normals, zeros where not recovered. ``albedo`` (H, W): ρ̂, zeros
    where not recovered. ``count``: usable lights per pixel. ``valid``: pixels recovered.
    ``mask``: the pixels that were considered (the object)."""

    normals: Array
    albedo: Array
    count: NDArray[np.int64]
    valid: NDArray[np.bool_]
    mask: NDArray[np.bool_]

    def angular_error(self, reference: ArrayLike) -> Array:
        """Angle (deg) between the recovered and ``reference`` (H, W, 3) unit normals, NaN where not
        recovered."""
        ref = np.asarray(reference, float)
        if ref.shape != self.normals.shape:
            raise OptlightError(
                f"reference normals of shape {ref.shape} for a recovery of {self.normals.shape}"
            )
        cos = np.clip(np.einsum("hwk,hwk->hw", self.normals, ref), -1.0, 1.0)
        return np.where(self.valid, np.degrees(np.arccos(cos)), np.nan)

    def error_stats(self, reference: ArrayLike) -> dict[str, float]:
        """Mean, median and 95th percentile angular error (deg) over the recovered pixels, and the
        share of the considered pixels that were recovered (%)."""
        err = self.angular_error(reference)[self.valid]
        considered = int(self.mask.sum())
        stats = {"pixels": float(considered), "recovered_pct": 100.0 * err.size / max(considered, 1)}
        if err.size == 0:
            return {**stats, "mean_deg": float("nan"), "median_deg": float("nan"), "p95_deg": float("nan")}
        return {
            **stats,
            "mean_deg": float(err.mean()),
            "median_deg": float(np.median(err)),
            "p95_deg": float(np.percentile(err, 95)),
        }


def recover_normals(
    images: ArrayLike,
    directions: ArrayLike,
    intensities: ArrayLike | None = None,
    *,
    mask: ArrayLike | None = None,
    ambient: ArrayLike | None = None,
    saturation: float = 1.0,
    dark_level: float = 0.02,
    saturation_level: float = 0.98,
    min_lights: int = 3,
    file: str = "<api>",
    key: str = "lightset.count",
) -> NormalRecovery:
    """Least-squares photometric stereo (module docstring) from ``images`` (N, H, W).

    Args:
        directions: (N, 3) unit light directions (object towards light); normals come out in their frame.
        intensities: (N,) light strengths e_k in pixel units (default 1).
        mask: (H, W) pixels to solve (default all).
        ambient: (H, W) image with the light off, subtracted from every image (default 0).
        saturation: the pixel value where the sensor saturates, s.
        dark_level, saturation_level: usable-light thresholds in normalised luminance.
        min_lights: fewest usable lights for a pixel to be solved (at least 3).

    Raises:
        ProblemError: fewer than 3 lights, naming ``file`` and ``key``.
        OptlightError: inconsistent shapes.
    """
    imgs = np.asarray(images, float)
    dirs = np.asarray(directions, float)
    n = len(dirs)
    if n < 3:
        raise ProblemError(file, key, "at least 3 lights for photometric stereo", n)
    if min_lights < 3:
        raise OptlightError(f"min_lights must be at least 3 (three unknowns per pixel), got {min_lights}")
    if imgs.ndim != 3 or imgs.shape[0] != n or dirs.shape != (n, 3):
        raise OptlightError(
            f"photometric stereo needs images (N, H, W) and directions (N, 3); got {imgs.shape}, {dirs.shape}"
        )
    if not np.allclose(np.linalg.norm(dirs, axis=1), 1.0, atol=1e-6):
        raise OptlightError("light directions must be unit vectors")
    e = np.ones(n) if intensities is None else np.asarray(intensities, float).reshape(n)
    h, w = imgs.shape[1:]
    considered = np.ones((h, w), bool) if mask is None else np.asarray(mask, bool)
    amb = np.zeros((h, w)) if ambient is None else np.asarray(ambient, float)
    if considered.shape != (h, w) or amb.shape != (h, w):
        raise OptlightError(f"mask and ambient must be ({h}, {w}) images")

    pix = np.flatnonzero(considered.ravel())
    raw = imgs.reshape(n, -1)[:, pix].T  # (P, N)
    signal = raw - amb.ravel()[pix, None]
    usable = (signal / saturation > dark_level) & (raw / saturation < saturation_level)
    rows = e[:, None] * dirs  # (N, 3): e_k l_k
    wu = usable.astype(float)
    m = np.einsum("pk,ka,kb->pab", wu, rows, rows)
    r = np.einsum("pk,ka->pa", wu * signal, rows)
    count = usable.sum(axis=1)
    eig = np.linalg.eigvalsh(m)
    solvable = (count >= min_lights) & (eig[:, 0] > MIN_CONDITION * np.maximum(eig[:, -1], 1e-300))
    b = np.zeros((pix.size, 3))
    if solvable.any():
        b[solvable] = np.linalg.solve(m[solvable], r[solvable][..., None])[..., 0]
    rho = np.linalg.norm(b, axis=1)
    solvable &= rho > 0
    normals = np.zeros((h * w, 3))
    albedo = np.zeros(h * w)
    counts = np.zeros(h * w, np.int64)
    valid = np.zeros(h * w, bool)
    normals[pix[solvable]] = b[solvable] / rho[solvable, None]
    albedo[pix[solvable]] = rho[solvable]
    counts[pix] = count
    valid[pix] = solvable
    return NormalRecovery(
        normals.reshape(h, w, 3), albedo.reshape(h, w), counts.reshape(h, w), valid.reshape(h, w), considered
    )


# --------------------------------------------------------------------------------------------
# The model camera
# --------------------------------------------------------------------------------------------


def render_set(scene: Scene, directions: ArrayLike, noise: bool | np.random.Generator = False) -> Array:
    """The images (N, H, W) of the NumPy renderer (shadow rays) for lights at directions (N, 3) in the
    sphere frame, ``a = O + b R_WS d``."""
    sphere = scene.sphere
    positions = sphere.center + sphere.radius * np.asarray(directions, float) @ sphere.rotation.T
    return np.stack([scene.render(a, noise=noise) for a in positions])


def ambient_image(scene: Scene) -> Array:
    """The image (H, W) with the light off: g ρ k_amb on the object, 0 elsewhere."""
    light = scene.light
    return scene.to_image(np.clip(light.gain * scene.gbuffer.albedo * light.ambient, 0.0, light.saturation))


def gbuffer_normal_map(scene: Scene) -> Array:
    """The G-buffer's unit normals as an (H, W, 3) image, world frame, zeros off the object."""
    h, w = scene.gbuffer.mask.shape
    out = np.zeros((h * w, 3))
    out[scene.gbuffer.pixel_index] = scene.gbuffer.normals
    return out.reshape(h, w, 3)


def recover_from_scene(
    scene: Scene,
    directions: ArrayLike,
    images: ArrayLike,
    dark_level: float = 0.02,
    saturation_level: float = 0.98,
) -> NormalRecovery:
    """:func:`recover_normals` for images of ``scene`` under lights at sphere-frame ``directions``:
    the images as the scene renders them, linearised by its response (``scene.response_gamma``, a
    calibrated model's), world-frame light directions, strengths ``gain · power``, the object mask,
    the model's ambient image subtracted; the normals come out in the world frame (compare with
    :func:`gbuffer_normal_map`). Assumes the directional light model."""
    light = scene.light
    world = np.asarray(directions, float) @ scene.sphere.rotation.T
    if scene.response_gamma != 1.0:
        images = linearise(images, light.saturation, scene.response_gamma)
    return recover_normals(
        images,
        world,
        np.full(len(world), light.gain * light.power),
        mask=scene.gbuffer.mask,
        ambient=ambient_image(scene),
        saturation=light.saturation,
        dark_level=dark_level,
        saturation_level=saturation_level,
    )


# --------------------------------------------------------------------------------------------
# Figures
# --------------------------------------------------------------------------------------------


def normal_map_figure(normals: ArrayLike, valid: ArrayLike, title: str = "normal map") -> Figure:
    """The normals (H, W, 3) as RGB = (n + 1)/2 (the usual normal-map colours; pass them in the
    DiLiGenT axes x right, y up, z towards the camera), black where not ``valid``."""
    from matplotlib.figure import Figure

    n = np.asarray(normals, float)
    rgb = np.where(np.asarray(valid, bool)[..., None], np.clip((n + 1.0) / 2.0, 0.0, 1.0), 0.0)
    fig = Figure(figsize=(4.2, 4.2))
    ax = fig.add_subplot()
    ax.imshow(rgb, interpolation="nearest")
    ax.set_title(title)
    ax.set_axis_off()
    return fig


def error_map_figure(error_deg: ArrayLike, title: str = "angular error", vmax: float | None = None) -> Figure:
    """The angular error (H, W) in degrees with a colour bar; NaN (not recovered, off the object)
    is left blank. ``vmax`` defaults to the 99th percentile of the error."""
    from matplotlib.figure import Figure

    err = np.asarray(error_deg, float)
    finite = err[np.isfinite(err)]
    top = vmax if vmax is not None else (float(np.percentile(finite, 99)) if finite.size else 1.0)
    fig = Figure(figsize=(5.0, 4.2))
    ax = fig.add_subplot()
    image = ax.imshow(
        np.ma.masked_invalid(err), cmap="magma", vmin=0.0, vmax=max(top, 1e-9), interpolation="nearest"
    )
    fig.colorbar(image, ax=ax, label="degrees")
    ax.set_title(title)
    ax.set_axis_off()
    return fig


def recovery_report(recovery: NormalRecovery, reference: ArrayLike) -> dict[str, Any]:
    """Error statistics (:meth:`NormalRecovery.error_stats`) and the usable-light counts (min,
    median, max over the considered pixels), for plan.json."""
    counts = recovery.count[recovery.mask]
    return {
        **recovery.error_stats(reference),
        "usable_lights": {
            "min": int(counts.min(initial=0)),
            "median": float(np.median(counts)) if counts.size else 0.0,
            "max": int(counts.max(initial=0)),
        },
    }
