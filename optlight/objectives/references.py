"""What an objective compares with: the reference histogram and, where there is one, the reference
pixels, from pixels, given bins, an image file (read and sized to the camera) or a reference light."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike, NDArray

from optlight.errors import OptlightError, ProblemError
from optlight.objectives.histogram import SoftHistogram

if TYPE_CHECKING:
    from optlight.scene import Scene

Array = NDArray[np.float64]
Index = NDArray[np.intp]

@dataclass(frozen=True)
class Reference:
    """What the image is compared with, sampled at the object's pixels.

    ``histogram`` (K,) sums to 1; ``pixels`` (P_sel,) are the reference's normalised luminance at the
    compared pixels (None for given bins); ``selection`` indexes the compared pixels among the
    object's P pixels (None = all of them); ``label`` says where the reference came from."""

    histogram: Array
    pixels: Array | None
    selection: Index | None
    label: str


def reference_from_pixels(
    histogram: SoftHistogram, pixels: ArrayLike, selection: ArrayLike | None, label: str
) -> Reference:
    """A reference from normalised luminance at the object's pixels (P,), restricted to ``selection``."""
    u = np.asarray(pixels, float)
    sel = None if selection is None else np.asarray(selection, np.intp)
    u = u if sel is None else u[sel]
    return Reference(histogram.numpy(u), u, sel, label)


def reference_from_bins(bins: ArrayLike, label: str = "given bins") -> Reference:
    """A reference from given histogram bins, renormalised to sum 1."""
    b = np.asarray(bins, float)
    if b.ndim != 1 or (b < 0).any() or b.sum() <= 0:
        raise OptlightError(f"reference bins must be non-negative with a positive sum, got {b}")
    return Reference(b / b.sum(), None, None, label)


def read_image(path: Path, saturation: float, file: str = "<api>", key: str = "") -> Array:
    """A greyscale image as normalised luminance (H, W).

    PNG (or anything Pillow reads): integer values over their full scale (8-bit /255, 16-bit
    /65535), 32-bit float as is, colour converted to luma 0.2126 R + 0.7152 G + 0.0722 B. NPY: pixel values in the
    renderer's units (as :meth:`Scene.render` returns them), divided by ``saturation``; a trailing
    axis of 3 or 4 channels is converted to luma likewise. Errors name ``file`` and ``key``."""
    expected = "a greyscale or RGB image, PNG or NPY"
    try:
        if path.suffix.lower() == ".npy":
            img = np.load(path, allow_pickle=False).astype(float) / saturation
        else:
            img = _read_png(path)
    except (OSError, ValueError) as e:
        raise ProblemError(file, key, expected, f"{path} ({e})") from None
    if img.ndim == 3 and img.shape[2] in (3, 4):
        img = img[..., :3] @ np.array([0.2126, 0.7152, 0.0722])
    if img.ndim != 2 or not np.isfinite(img).all():
        raise ProblemError(file, key, expected, f"{path} with shape {img.shape}")
    return img


def _read_png(path: Path) -> Array:
    """16-bit greyscale /65535, 8-bit greyscale or RGB(A) /255, 32-bit float as is; any other mode
    (bilevel, palette, …) through Pillow's conversion to 8-bit greyscale."""
    from PIL import Image

    with Image.open(path) as im:
        if im.mode in ("I;16", "I;16B", "I;16L", "I"):
            return np.asarray(im).astype(float) / 65535.0
        if im.mode == "F":
            return np.asarray(im).astype(float)
        if im.mode in ("RGB", "RGBA"):
            return np.asarray(im).astype(float) / 255.0
        return np.asarray(im.convert("L")).astype(float) / 255.0


def resize_image(img: Array, width: int, height: int, nearest: bool = False) -> Array:
    """``img`` (H, W) resampled to (height, width): bilinear, or nearest for masks."""
    if img.shape == (height, width):
        return img
    from PIL import Image

    resample = Image.Resampling.NEAREST if nearest else Image.Resampling.BILINEAR
    return np.asarray(
        Image.fromarray(img.astype(np.float32), mode="F").resize((width, height), resample), float
    )


def reference_from_image(
    scene: Scene,
    histogram: SoftHistogram,
    image: Path,
    mask: Path | None = None,
    saturation: float = 1.0,
    file: str = "<api>",
    size: tuple[int, int] | None = None,
) -> Reference:
    """A reference from an image file, sampled at the object's pixels of ``scene``.

    ``size`` (width, height): the size the image and the mask must have (the problem's camera; a
    :class:`ProblemError` with both sizes otherwise), or None to take any size. The image is then
    resized (bilinear) to ``scene``'s camera, which renders the search at a lower resolution.
    ``mask`` (non-zero = compared, resized by nearest neighbour) restricts the compared pixels to
    the object pixels it covers; the rendered image is restricted to the same pixels."""
    cam, gb = scene.camera, scene.gbuffer
    key = "objective.reference.image"
    img = _sized(read_image(image, saturation, file, key), size, image, file, key)
    img = resize_image(img, cam.width, cam.height)
    selection = None
    if mask is not None:
        key = "objective.reference.mask"
        m = _sized(read_image(mask, 1.0, file, key), size, mask, file, key)
        m = resize_image(m, cam.width, cam.height, nearest=True)
        selection = np.flatnonzero(m.ravel()[gb.pixel_index] != 0)
        if selection.size == 0:
            raise ProblemError(
                file, "objective.reference.mask", "a mask covering some object pixels", str(mask)
            )
    return reference_from_pixels(histogram, img.ravel()[gb.pixel_index], selection, f"image {image.name}")


def _sized(img: Array, size: tuple[int, int] | None, path: Path, file: str, key: str) -> Array:
    """``img`` when ``size`` (width, height) is None or its size; else a :class:`ProblemError` naming
    ``key`` with both sizes: an image of another size would be stretched to the camera's."""
    if size is not None and img.shape != (size[1], size[0]):
        raise ProblemError(
            file,
            key,
            f"an image of the camera's size, {size[0]} × {size[1]} px (camera.width × camera.height), or "
            "objective.reference.resize = true to resize it",
            f"{path.name} of {img.shape[1]} × {img.shape[0]} px",
        )
    return img


def reference_from_light(
    scene: Scene, histogram: SoftHistogram, zenith: float, azimuth: float, saturation: float = 1.0
) -> Reference:
    """A reference rendered (NumPy renderer, shadow rays) with the light at ``zenith``, ``azimuth`` (rad)."""
    pixels = scene.pixels(scene.sphere.position(zenith, azimuth)) / saturation
    label = f"light at zenith {np.rad2deg(zenith):g}°, azimuth {np.rad2deg(azimuth):g}°"
    return reference_from_pixels(histogram, pixels, None, label)
