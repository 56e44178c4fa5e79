"""Cameras in the loop (docs/design.md §11): a light pose in, a captured image and its exposure out.

A :class:`CaptureCamera` has one method, ``capture(light_position, index) -> Capture``. Three
implementations:

- :class:`ModelCamera`: the NumPy renderer of the model scene, changed as far as a Lambertian model
  can be by the problem's ``[world]`` section (light power, ambient, albedo, light position error,
  response, noise);
- :class:`optlight.capture.mitsuba.MitsubaCamera`: Mitsuba 3 renders the same mesh with the whole
  ``[world]`` (non-Lambertian BSDF, inter-reflections, a light of finite size with an angular
  emission profile, ambient light, response, noise);
- :class:`optlight.capture.folder.FolderCamera`: the files a real camera wrote, matched to the
  captures by ``captures.csv``.

The world of the model and physically based cameras. The robot puts the nominal light frame at a with
rotation R (world, m; the light emits along its +z); the real lamp is at a' = a + R·δ_L + δ
(δ_L = ``lamp_offset_m``, on the flange, in the light frame: it turns with the arm; δ = ``light_offset_m``
in the world frame) with its axis R·R_L·ẑ (R_L from ``lamp_rpy_deg``), of power E' = ``power_scale``·E;
a capture without R (the servo's, a reference photograph) takes R_L = I and δ_L = 0. The ambient is k' (the
model's unless ``ambient`` is set); the albedo at a surface point x is

    ρ'(x) = ``albedo_scale`` · ρ(x) · (1 + t sin(2πx₁/λ) sin(2πx₂/λ) sin(2πx₃/λ)),

t = ``albedo_texture``, λ = ``texture_period_m`` (world coordinates, m). The linear pixel value I
(renderer units, the model's gain g) gets sensor noise η ~ N(0, σ²) (σ = ``noise_std``), is clipped
to [0, s] and passes the camera response: the recorded value is Y = s·(clip(I + η, 0, s)/s)^(1/γ),
γ = ``gamma``. A :class:`Capture` holds Y: what the camera delivers, before any calibration.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray
from PIL import Image

from optlight.scene import Scene
from optlight.spec import LightSpec, WorldSpec

Array = NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class Capture:
    """One captured image.

    ``image`` (H, W): the recorded values Y in the renderer's units (``saturation`` is full scale);
    ``light_position`` (3,): where the robot put the nominal light frame (world, m), which the
    calibration takes as the light's position up to the lamp's offset on the flange;
    ``light_rotation`` (3, 3): that frame's rotation in the world (None when the pose is not known, as
    for the servo's captures: the lamp calibration leaves the capture out); ``index``: the capture's
    number in its plan; ``exposure``: what the camera reports about the shot (camera kind, gain,
    saturation, response applied to the file, samples, file name …)."""

    image: Array
    light_position: Array
    index: int = 0
    exposure: Mapping[str, Any] = field(default_factory=dict)
    light_rotation: Array | None = None


class CaptureCamera(Protocol):
    """A camera that captures an image for a light pose.

    (Named so because :class:`optlight.scene.Camera` is the pinhole model every camera shares.)"""

    #: "model", "mitsuba" or "folder".
    kind: str

    def capture(self, light_position: ArrayLike, index: int = 0, light_rotation: ArrayLike | None = None) -> Capture:
        """The image with the nominal light frame at ``light_position`` (world, m) and
        ``light_rotation`` (3, 3; None: unknown); ``index`` is the capture's number in its plan (the
        folder camera reports it when no file matches)."""
        ...


def real_lamp(light_position: ArrayLike, light_rotation: ArrayLike | None, world: WorldSpec) -> tuple[Array, Array | None]:
    """The real lamp's position a' = a + R·δ_L + δ (world, m) and axis R·R_L·ẑ (None without R) of the
    module docstring for the nominal light frame at ``light_position`` a with ``light_rotation`` R."""
    a = np.asarray(light_position, float) + np.asarray(world.light_offset_m, float)
    if light_rotation is None:
        return a, None
    rotation = np.asarray(light_rotation, float)
    tilt = _rpy_matrix(world.lamp_rpy_deg)
    return a + rotation @ np.asarray(world.lamp_offset_m, float), rotation @ tilt[:, 2]


def _rpy_matrix(rpy_deg: ArrayLike) -> Array:
    """R = Rz(yaw)·Ry(pitch)·Rx(roll) of URDF roll, pitch, yaw (deg), as the robot's light frame."""
    r, p, y = np.deg2rad(np.asarray(rpy_deg, float))
    cr, sr, cp, sp, cy, sy = np.cos(r), np.sin(r), np.cos(p), np.sin(p), np.cos(y), np.sin(y)
    rz = np.array([[cy, -sy, 0.0], [sy, cy, 0.0], [0.0, 0.0, 1.0]])
    ry = np.array([[cp, 0.0, sp], [0.0, 1.0, 0.0], [-sp, 0.0, cp]])
    rx = np.array([[1.0, 0.0, 0.0], [0.0, cr, -sr], [0.0, sr, cr]])
    return rz @ ry @ rx


def world_albedo(points: ArrayLike, albedo: ArrayLike, world: WorldSpec) -> Array:
    """ρ'(x) of the module docstring at surface points x (N, 3) with model albedo ρ (N,)."""
    x = 2.0 * np.pi * np.asarray(points, float) / world.texture_period_m
    texture = 1.0 + world.albedo_texture * np.sin(x[:, 0]) * np.sin(x[:, 1]) * np.sin(x[:, 2])
    return world.albedo_scale * np.asarray(albedo, float) * texture


def world_light(light: LightSpec, world: WorldSpec) -> LightSpec:
    """The model's light with the world's power E', ambient k', noise σ and seed."""
    return dataclasses.replace(
        light,
        power=light.power * world.power_scale,
        ambient=light.ambient if world.ambient is None else world.ambient,
        noise_std=world.noise_std,
        seed=world.seed,
    )


class ModelCamera:
    """The model camera: the scene's NumPy renderer (shadow rays) in the world of ``world`` (see the
    module docstring) as far as the Lambertian model goes; BSDF, inter-reflection and the light's size
    and profile are the physically based camera's. ``scene`` is the model scene at the camera's
    resolution; noise comes from one generator seeded by ``world.seed``, so a sequence of captures is
    reproducible."""

    kind = "model"

    def __init__(self, scene: Scene, world: WorldSpec) -> None:
        self.scene = scene
        self.world = world
        gb = scene.gbuffer
        self._world_scene = scene.calibrated(
            world_light(scene.light, world), world_albedo(gb.points, gb.albedo, world), response_gamma=world.gamma
        )
        self._rng = np.random.default_rng(world.seed)

    def capture(self, light_position: ArrayLike, index: int = 0, light_rotation: ArrayLike | None = None) -> Capture:
        """Render with the real lamp at a' (:func:`real_lamp`; the model's light has no axis); noise,
        clip and response as in the module docstring."""
        a = np.asarray(light_position, float)
        real, _ = real_lamp(a, light_rotation, self.world)
        noise = self._rng if self.world.noise_std > 0 else False
        image = self._world_scene.to_image(self._world_scene.pixels(real, noise=noise))
        exposure = {
            "camera": self.kind,
            "gain": self.scene.light.gain,
            "saturation": self.scene.light.saturation,
            "linearised_gamma": 1.0,
        }
        return Capture(image, a, index, exposure, _rotation(light_rotation))


def _rotation(light_rotation: ArrayLike | None) -> Array | None:
    """``light_rotation`` as a (3, 3) array, or None."""
    return None if light_rotation is None else np.asarray(light_rotation, float).reshape(3, 3)


def write_capture_png(path: str | Path, image: ArrayLike, saturation: float) -> Path:
    """Write recorded values (H, W) as a 16-bit greyscale PNG, 0 → 0 and ``saturation`` → 65535 (what a
    :class:`~optlight.capture.folder.FolderCamera` reads back, to 1/65535 of full scale)."""
    out = Path(path)
    values = np.clip(np.asarray(image, float) / saturation, 0.0, 1.0)
    out.parent.mkdir(parents=True, exist_ok=True)
    Image.fromarray(np.round(values * 65535).astype(np.uint16)).save(out)
    return out
