"""Exports for photometric-stereo tools: the DiLiGenT layout and recovered normals (docs/design.md §10, §12).

DiLiGenT layout (one folder per object):

- ``filenames.txt``: one image file name per line, in capture order (the names of the plan's
  captures.csv and lights.lp, ``[trajectory] image_pattern``);
- ``light_directions.txt``: N rows ``x y z``, unit vectors from the object towards the light;
- ``light_intensities.txt``: N rows ``r g b``, the light strengths, so that a Lambertian pixel is
  ``value / 65535 = ρ · intensity · (n·l)`` (a grey image repeats its strength in the three columns);
- ``mask.png``: 8-bit, 255 on the object, 0 elsewhere;
- the images: 16-bit greyscale PNG, ``round(65535 · clip(I / s, 0, 1))`` with ``s`` the saturation value.

Recovered maps: ``normals.npy`` (H, W, 3) float64, zeros outside the mask, and ``albedo.npy`` (H, W).

Directions and normals use DiLiGenT's axes, x to the right of the image, y towards its top, z towards
the camera; from the OpenCV camera frame (x right, y down, z forward) that is (x, −y, −z), as for
relight's ``lights.lp`` (:func:`optlight.export.lp_direction`).

The builders return ``{relative path: bytes}`` and write nothing; :func:`files_writer` turns such a
mapping into a writer for :func:`optlight.export.write_results` (which writes into a staging folder
that appears whole or not at all).
"""

from __future__ import annotations

import io
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path, PurePosixPath
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from PIL import Image

from optlight.errors import OptlightError
from optlight.export import lp_direction
from optlight.photometric_stereo import (
    error_map_figure,
    gbuffer_normal_map,
    normal_map_figure,
    recover_from_scene,
    recovery_report,
    render_set,
)

if TYPE_CHECKING:
    from matplotlib.figure import Figure

    from optlight.scene import Scene

Array = NDArray[np.float64]
Files = dict[str, bytes]

#: Full scale of the 16-bit images.
FULL_SCALE = 65535


def diligent_axes(vectors_camera: ArrayLike) -> Array:
    """Vectors (..., 3) from the OpenCV camera frame to DiLiGenT's axes: (x, −y, −z)."""
    return lp_direction(vectors_camera)


def _png(array: NDArray[np.generic]) -> bytes:
    buffer = io.BytesIO()
    Image.fromarray(array).save(buffer, format="PNG")
    return buffer.getvalue()


def _text(rows: Array) -> bytes:
    return "".join(" ".join(f"{x:.9f}" for x in row) + "\n" for row in rows).encode()


def _npy(array: Array) -> bytes:
    buffer = io.BytesIO()
    np.save(buffer, np.asarray(array, np.float64), allow_pickle=False)
    return buffer.getvalue()


def to_uint16(image: ArrayLike, saturation: float = 1.0) -> NDArray[np.uint16]:
    """``round(65535 · clip(I / s, 0, 1))`` of an image in renderer units."""
    u = np.clip(np.asarray(image, float) / saturation, 0.0, 1.0)
    return np.round(u * FULL_SCALE).astype(np.uint16)


def diligent_files(
    images: ArrayLike,
    directions_camera: ArrayLike,
    intensities: ArrayLike,
    mask: ArrayLike,
    *,
    saturation: float = 1.0,
    names: Sequence[str] | None = None,
) -> Files:
    """The DiLiGenT folder's files (module docstring) as ``{name: bytes}``.

    Args:
        images: (N, H, W) greyscale images in renderer units.
        directions_camera: (N, 3) unit vectors from the object towards each light, OpenCV camera frame.
        intensities: (N,) or (N, 3) light strengths in renderer units (``gain · power`` for the
            model camera); written divided by ``saturation``, i.e. in the images' 0–1 scale.
        mask: (H, W) object pixels.
        names: image file names (default ``001.png`` …).
    """
    imgs = np.asarray(images, float)
    dirs = np.asarray(directions_camera, float)
    n = len(dirs)
    if imgs.ndim != 3 or imgs.shape[0] != n or dirs.shape != (n, 3):
        raise OptlightError(
            f"DiLiGenT export needs images (N, H, W) and directions (N, 3); got {imgs.shape}, {dirs.shape}"
        )
    if not np.allclose(np.linalg.norm(dirs, axis=1), 1.0, atol=1e-6):
        raise OptlightError("light directions must be unit vectors")
    strength = np.asarray(intensities, float)
    strength = np.repeat(strength.reshape(n, 1), 3, axis=1) if strength.size == n else strength.reshape(n, 3)
    m = np.asarray(mask, bool)
    if m.shape != imgs.shape[1:]:
        raise OptlightError(f"mask of shape {m.shape} for images of {imgs.shape[1:]}")
    files = list(names) if names is not None else [f"{i + 1:03d}.png" for i in range(n)]
    if (
        len(files) != n
        or len(set(files)) != n
        or any(not f or any(c.isspace() for c in f) or "/" in f for f in files)
    ):
        raise OptlightError("image names must be N distinct plain file names without whitespace")
    out: Files = {
        "filenames.txt": "".join(f"{name}\n" for name in files).encode(),
        "light_directions.txt": _text(diligent_axes(dirs)),
        "light_intensities.txt": _text(strength / saturation),
        "mask.png": _png(np.where(m, 255, 0).astype(np.uint8)),
    }
    for name, image in zip(files, imgs, strict=True):
        out[name] = _png(to_uint16(image, saturation))
    return out


def recovery_files(normals_camera: ArrayLike, albedo: ArrayLike, mask: ArrayLike) -> Files:
    """``normals.npy`` (H, W, 3, DiLiGenT axes, zeros outside ``mask``) and ``albedo.npy`` (H, W,
    zeros outside ``mask``) from normals in the OpenCV camera frame."""
    n = np.asarray(normals_camera, float)
    m = np.asarray(mask, bool)
    a = np.asarray(albedo, float)
    if n.shape != (*m.shape, 3) or a.shape != m.shape:
        raise OptlightError(f"normals {n.shape}, albedo {a.shape} and mask {m.shape} do not match")
    return {
        "normals.npy": _npy(np.where(m[..., None], diligent_axes(n), 0.0)),
        "albedo.npy": _npy(np.where(m, a, 0.0)),
    }


def files_writer(files: Mapping[str, bytes], subfolder: str = "") -> Callable[[Path], list[Path]]:
    """A writer for :func:`optlight.export.write_results`: writes ``files`` under ``folder/subfolder``
    and returns the paths written. Names must be relative and stay inside the folder."""
    base = PurePosixPath(subfolder)
    for name in [*files, subfolder]:
        parts = PurePosixPath(name).parts
        if PurePosixPath(name).is_absolute() or ".." in parts:
            raise OptlightError(f"export file name {name!r} must be a relative path inside the folder")

    def write(folder: Path) -> list[Path]:
        written = []
        for name, data in files.items():
            path = Path(folder) / base / name
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_bytes(data)
            written.append(path)
        return written

    return write


@dataclass(frozen=True, eq=False)
class DiligentFolder:
    """A DiLiGenT folder as read back: ``names``, ``images`` (N, H, W) in [0, 1], ``directions``
    and ``intensities`` (N, 3), ``mask`` (H, W)."""

    names: tuple[str, ...]
    images: Array
    directions: Array
    intensities: Array
    mask: NDArray[np.bool_]


def read_diligent(folder: str | Path) -> DiligentFolder:
    """Read a DiLiGenT folder (greyscale or colour images, converted to luma for colour)."""
    root = Path(folder)
    try:
        names = tuple(s.strip() for s in (root / "filenames.txt").read_text().splitlines() if s.strip())
        directions = np.loadtxt(root / "light_directions.txt", ndmin=2)
        intensities = np.loadtxt(root / "light_intensities.txt", ndmin=2)
        with Image.open(root / "mask.png") as im:
            mask = np.asarray(im.convert("L")) > 0
        images = np.stack([_read_image(root / name) for name in names])
    except (OSError, ValueError) as e:
        raise OptlightError(f"{root}: not a readable DiLiGenT folder ({e})") from None
    if directions.shape != (len(names), 3) or intensities.shape != (len(names), 3):
        raise OptlightError(
            f"{root}: {len(names)} file names but directions {directions.shape}, intensities {intensities.shape}"
        )
    return DiligentFolder(names, images, directions, intensities, mask)


def _read_image(path: Path) -> Array:
    """16-bit grey /65535, 8-bit grey or RGB /255 (RGB to luma 0.2126 R + 0.7152 G + 0.0722 B)."""
    with Image.open(path) as im:
        if im.mode in ("I;16", "I;16B", "I;16L", "I"):
            return np.asarray(im).astype(float) / FULL_SCALE
        if im.mode in ("RGB", "RGBA"):
            return np.asarray(im)[..., :3].astype(float) @ np.array([0.2126, 0.7152, 0.0722]) / 255.0
        return np.asarray(im.convert("L")).astype(float) / 255.0


@dataclass(frozen=True, eq=False)
class ModelCapture:
    """A light set captured by the model camera: the DiLiGenT folder's files and the recovered
    normals and albedo (``files``, names relative to the folder), the figures ``normal_map`` and
    ``normal_error``, and the recovery's error statistics against the G-buffer normals (``stats``,
    :func:`~optlight.photometric_stereo.recovery_report`)."""

    files: Files
    figures: dict[str, Figure]
    stats: dict[str, Any]


def model_capture(
    scene: Scene,
    directions: ArrayLike,
    dark_level: float = 0.02,
    saturation_level: float = 0.98,
    names: Sequence[str] | None = None,
) -> ModelCapture:
    """Render the lights at sphere-frame ``directions`` (N, 3) with the NumPy renderer (shadow rays),
    recover the normals from those images (:func:`~optlight.photometric_stereo.recover_from_scene`,
    the directional model) and package both in the DiLiGenT layout (x right, y up, z towards the
    camera): the images, light directions and intensities (``gain · power``), the mask, and
    ``normals.npy`` / ``albedo.npy``. ``names``: the images' file names (default ``001.png`` …)."""
    d = np.asarray(directions, float)
    images = render_set(scene, d)
    recovery = recover_from_scene(scene, d, images, dark_level, saturation_level)
    camera, light = scene.camera, scene.light
    to_camera = camera.to_camera_frame
    normals_camera = to_camera(recovery.normals.reshape(-1, 3)).reshape(recovery.normals.shape)
    files = {
        **diligent_files(
            images,
            to_camera(d @ scene.sphere.rotation.T),
            np.full(len(d), light.gain * light.power),
            scene.gbuffer.mask,
            saturation=light.saturation,
            names=names,
        ),
        **recovery_files(normals_camera, recovery.albedo, recovery.valid),
    }
    error = recovery.angular_error(gbuffer_normal_map(scene))
    figures = {
        "normal_map": normal_map_figure(diligent_axes(normals_camera), recovery.valid, "recovered normals"),
        "normal_error": error_map_figure(error, "angular error vs the model's normals"),
    }
    return ModelCapture(files, figures, recovery_report(recovery, gbuffer_normal_map(scene)))
