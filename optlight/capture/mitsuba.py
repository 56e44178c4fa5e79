"""The physically based camera: Mitsuba 3 renders the model's mesh in the world of ``[world]``.

Mitsuba is an optional dependency (``pip install 'optlight[mitsuba]'``). The variant is chosen at
run time (docs/design.md §7): ``llvm_ad_rgb`` when Debian's LLVM 19 library is found (``DRJIT_LIBLLVM_PATH``
is set to it unless already set), ``scalar_rgb`` otherwise; the system's LLVM 14/15 crash the LLVM
variant, so it is never tried without LLVM 19.

Units, so that a Lambertian world renders what the model renders (checked pixel by pixel in
``tests/capture/test_capture.py``). Mitsuba's diffuse BSDF reflects L_o = (ρ/π)·E_irr·cos θ, and a pixel is
the gain g times the radiance it sees, so

- point light: intensity π·E'·b² (irradiance E'·(b/r)² cos θ at distance r, the model's falloff);
- directional light (the model's, with a point-sized isotropic world light): irradiance π·E' along
  O − a';
- a sphere light of radius R: radiance π·E'·b²/(πR²) (the same intensity in every direction); a disk
  facing O: the same radiance, so its intensity on the axis is that of the point light and falls off
  as cos of the angle to the axis (a Lambertian emitter); a spot: the point intensity inside a cone of
  half-angle ``spot_cutoff_deg``, smoothly falling off from 3/4 of it;
- ambient: a constant environment of radiance k' (a diffuse surface open to the whole sky reflects
  ρ·k', the model's ambient term; an occluded one less).

Camera: Mitsuba's camera frame is (left, up, forward) where ours is OpenCV's (right, down, forward),
so ``to_world`` is [x y z]·diag(−1, −1, 1); the vertical field of view is 2 atan(H/(2 f_y)) and the
principal point offset is −(c − (N − 1)/2)/N of the image size on each axis (pixel centres at integers
in our convention). A box pixel filter averages over the pixel, where our renderer samples its centre.
Emitters seen directly are hidden: the background is 0, as in our renderer.
Square pixels (f_x = f_y) only.
"""

from __future__ import annotations

import glob
import os
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from optlight.capture import Array, Capture, real_lamp, world_albedo, world_light
from optlight.errors import OptlightError, ProblemError
from optlight.scene import Scene
from optlight.scene.response import respond
from optlight.spec import WorldSpec

#: Where Debian's ``libllvm19`` installs libLLVM (``dpkg -L libllvm19``).
LLVM19_GLOBS = ("/usr/lib/*-linux-gnu/libLLVM.so.19*", "/usr/lib/llvm-19/lib/libLLVM.so.19*")


def llvm19_library() -> str | None:
    """The path of LLVM 19's shared library, if installed."""
    found = sorted(p for pattern in LLVM19_GLOBS for p in glob.glob(pattern))
    return found[0] if found else None


def load_mitsuba(variant: str = "auto") -> Any:
    """The ``mitsuba`` module with ``variant`` set ("auto": LLVM when LLVM 19 is there, see the module
    docstring). Raises :class:`OptlightError` when Mitsuba is not installed."""
    if variant == "auto":
        library = os.environ.get("DRJIT_LIBLLVM_PATH") or llvm19_library()
        if library and "DRJIT_LIBLLVM_PATH" not in os.environ:
            os.environ["DRJIT_LIBLLVM_PATH"] = library
        variant = "llvm_ad_rgb" if library else "scalar_rgb"
    try:
        import mitsuba as mi
    except ImportError:
        raise OptlightError(
            "the physically based camera needs Mitsuba 3: pip install 'optlight[mitsuba]'"
        ) from None
    if variant not in mi.variants():
        raise OptlightError(f"Mitsuba variant {variant!r} is not available (have {', '.join(mi.variants())})")
    mi.set_variant(variant)
    return mi


class MitsubaCamera:
    """Mitsuba 3 renders of ``scene``'s object (its mesh, or the exact sphere) seen by ``scene``'s camera
    in the world of ``world`` (module docstring); ``spp`` and ``bounces`` from ``world``. Each capture
    has its own sample seed (``world.seed`` + the capture's count), and sensor noise from one generator
    seeded by ``world.seed``."""

    kind = "mitsuba"

    def __init__(self, scene: Scene, world: WorldSpec, variant: str = "auto", file: str = "<api>") -> None:
        cam = scene.camera
        if not np.isclose(cam.fx, cam.fy, rtol=1e-9):
            raise ProblemError(file, "camera.fy_px", f"square pixels (fy_px = fx_px = {cam.fx:g}) for Mitsuba", cam.fy)
        self.mi = load_mitsuba(variant)
        self.scene = scene
        self.world = world
        self.light = world_light(scene.light, world)
        self._rng = np.random.default_rng(world.seed)
        self._count = 0
        self._ambient: Array | None = None
        self._sensor = self._sensor_dict()
        self._shape = self._shape_dict()

    @property
    def variant(self) -> str:
        """The Mitsuba variant in use."""
        return str(self.mi.variant())

    def _sensor_dict(self) -> dict[str, Any]:
        cam = self.scene.camera
        to_world = np.eye(4)
        to_world[:3, :3] = cam.rotation @ np.diag([-1.0, -1.0, 1.0])
        to_world[:3, 3] = cam.position
        return {
            "type": "perspective",
            "fov": float(np.rad2deg(2.0 * np.arctan(0.5 * cam.height / cam.fy))),
            "fov_axis": "y",
            "principal_point_offset_x": -(cam.cx - (cam.width - 1) / 2) / cam.width,
            "principal_point_offset_y": -(cam.cy - (cam.height - 1) / 2) / cam.height,
            "to_world": self.mi.ScalarTransform4f(to_world.tolist()),
            "film": {
                "type": "hdrfilm",
                "width": cam.width,
                "height": cam.height,
                "rfilter": {"type": "box"},
                "pixel_format": "luminance",
            },
        }

    def _bsdf(self, reflectance: dict[str, Any]) -> dict[str, Any]:
        """The world's BSDF with the diffuse ``reflectance`` (a texture dict; a constant one for
        roughplastic, see :meth:`_vertex_bsdf`)."""
        w = self.world
        if w.bsdf == "lambertian":
            return {"type": "diffuse", "reflectance": reflectance}
        if w.bsdf == "roughplastic":
            return self._roughplastic(reflectance)
        return {"type": "principled", "base_color": reflectance, "roughness": w.roughness, "specular": w.specular}

    def _roughplastic(self, reflectance: dict[str, Any]) -> dict[str, Any]:
        """Mitsuba's roughplastic (GGX, α = roughness) with the diffuse ``reflectance``."""
        w = self.world
        return {
            "type": "roughplastic",
            "distribution": "ggx",
            "alpha": w.roughness,
            "diffuse_reflectance": reflectance,
            "specular_reflectance": {"type": "rgb", "value": [w.specular] * 3},
        }

    def _vertex_bsdf(self, top: float) -> dict[str, Any]:
        """The world's BSDF with the per-vertex diffuse albedo of the mesh attribute ``vertex_color``
        (3 channels); for roughplastic, of ``vertex_weight`` (1 channel): the albedo over its largest
        value ``top`` (> 0).

        Mitsuba's roughplastic takes no vertex colours: it weighs its specular and diffuse samples by
        the reflectance texture's mean, which a mesh attribute does not have. Its BSDF (the linear
        diffuse term, ``nonlinear`` false) is f_ρ = f_0 + ρ·(f_1 − f_0), so with ρ_max the largest
        albedo it is the blend (1 − ρ/ρ_max)·f_0 + (ρ/ρ_max)·f_ρmax of two roughplastics of constant
        reflectance, a ``blendbsdf`` weighted by ``vertex_weight``."""
        if self.world.bsdf != "roughplastic":
            return self._bsdf({"type": "mesh_attribute", "name": "vertex_color"})
        return {
            "type": "blendbsdf",
            "weight": {"type": "mesh_attribute", "name": "vertex_weight"},
            "bsdf_0": self._roughplastic({"type": "uniform", "value": 0.0}),
            "bsdf_1": self._roughplastic({"type": "uniform", "value": top}),
        }

    def _shape_dict(self) -> Any:
        """The object: Mitsuba's exact sphere for an untextured sphere object, else the mesh with
        smooth vertex normals and the world albedo as a vertex attribute."""
        mi, obj, w = self.mi, self.scene.object, self.world
        if obj.sphere is not None and w.albedo_texture == 0.0 and np.ptp(obj.albedo) == 0.0:
            rho = float(w.albedo_scale * obj.albedo[0])
            center, radius = obj.sphere
            return {
                "type": "sphere",
                "center": np.asarray(center, float).tolist(),
                "radius": float(radius),
                # uniform, not rgb: an rgb reflectance must lie in [0, 1], and albedo_scale may pass 1
                "bsdf": self._bsdf({"type": "uniform", "value": rho}),
            }
        mesh = obj.mesh
        vector = (lambda x: x) if mi.variant().startswith("scalar") else mi.Float
        index = (lambda x: x) if mi.variant().startswith("scalar") else mi.UInt32
        albedo = world_albedo(mesh.vertices, obj.albedo, w)
        top = max(float(np.max(albedo, initial=0.0)), 1e-12)
        props = mi.Properties()
        props["bsdf"] = mi.load_dict(self._vertex_bsdf(top))
        shape = mi.Mesh("object", len(mesh.vertices), len(mesh.faces), props, has_vertex_normals=True)
        params = mi.traverse(shape)
        params["vertex_positions"] = vector(np.asarray(mesh.vertices, np.float32).ravel())
        params["faces"] = index(np.asarray(mesh.faces, np.uint32).ravel())
        params["vertex_normals"] = vector(np.asarray(mesh.vertex_normals, np.float32).ravel())
        params.update()
        shape.add_attribute("vertex_color", 3, vector(np.repeat(albedo, 3).astype(np.float32)))
        if w.bsdf == "roughplastic":
            shape.add_attribute("vertex_weight", 1, vector((albedo / top).astype(np.float32)))
        return shape

    def _emitter(self, real: Array, axis: Array | None = None) -> dict[str, Any]:
        """The light at ``real`` (a', world, m) per the module docstring, a disk or spot facing along
        ``axis`` (the real lamp's, world; None: facing O)."""
        mi, w = self.mi, self.world
        center, radius = self.scene.sphere.center, self.scene.sphere.radius
        intensity = np.pi * self.light.power * radius**2
        if w.light_radius_m == 0.0 and w.light_profile == "isotropic":
            if self.light.model == "directional":
                return {
                    "type": "directional",
                    "direction": (center - real).tolist(),
                    "irradiance": {"type": "uniform", "value": np.pi * self.light.power},
                }
            return {"type": "point", "position": real.tolist(), "intensity": {"type": "uniform", "value": intensity}}
        axis = center - real if axis is None else axis
        up = np.array([0.0, 0.0, 1.0]) if abs(axis[2]) < 0.99 * np.linalg.norm(axis) else np.array([1.0, 0.0, 0.0])
        target = real + axis / np.linalg.norm(axis)
        aim = mi.ScalarTransform4f().look_at(origin=real.tolist(), target=target.tolist(), up=up.tolist())
        if w.light_profile == "spot":
            return {
                "type": "spot",
                "to_world": aim,
                "intensity": {"type": "uniform", "value": intensity},
                "cutoff_angle": w.spot_cutoff_deg,
                "beam_width": 0.75 * w.spot_cutoff_deg,
            }
        r = w.light_radius_m
        area = {"type": "area", "radiance": {"type": "uniform", "value": intensity / (np.pi * r * r)}}
        if w.light_profile == "isotropic":
            return {"type": "sphere", "center": real.tolist(), "radius": r, "emitter": area}
        return {"type": "disk", "to_world": aim @ mi.ScalarTransform4f().scale([r, r, 1.0]), "emitter": area}

    def _render(self, emitter: dict[str, Any], spp: int, seed: int) -> Array:
        """Radiance image (H, W) of the object lit by ``emitter`` alone (a scene-dict entry)."""
        mi = self.mi
        scene = {
            "type": "scene",
            "integrator": {"type": "path", "max_depth": self.world.bounces + 1, "hide_emitters": True},
            "sensor": {**self._sensor, "sampler": {"type": "independent", "sample_count": spp}},
            "object": self._shape,
            "light": emitter,
        }
        image = np.asarray(mi.render(mi.load_dict(scene), spp=spp, seed=seed), float)
        return image.reshape(image.shape[0], image.shape[1])

    def ambient_radiance(self) -> Array:
        """The radiance image (H, W) under the ambient light alone, rendered once at 4 × spp and kept:
        light transport is linear in the emitters, so each capture adds it to its own render of the
        light (one emitter per render also avoids the variance of choosing between emitters)."""
        if self._ambient is None:
            if self.light.ambient > 0:
                constant = {"type": "constant", "radiance": {"type": "uniform", "value": self.light.ambient}}
                self._ambient = self._render(constant, 4 * self.world.spp, self.world.seed + 1_000_003)
            else:
                self._ambient = np.zeros((self.scene.camera.height, self.scene.camera.width))
        return self._ambient

    def render_linear(self, light_position: ArrayLike, seed: int = 0, light_rotation: ArrayLike | None = None) -> Array:
        """The linear image g·(L_light + L_ambient) (H, W) with the robot's nominal light frame at
        ``light_position`` and ``light_rotation`` (the real lamp where :func:`real_lamp` puts it),
        before noise, clip and response."""
        real, axis = real_lamp(light_position, light_rotation, self.world)
        direct = self._render(self._emitter(real, axis), self.world.spp, seed)
        return self.light.gain * (direct + self.ambient_radiance())

    def capture(self, light_position: ArrayLike, index: int = 0, light_rotation: ArrayLike | None = None) -> Capture:
        """Render (:meth:`render_linear`), add noise, clip and apply the response."""
        seed = self.world.seed + self._count
        self._count += 1
        linear = self.render_linear(light_position, seed, light_rotation)
        if self.world.noise_std > 0:
            linear = linear + self._rng.normal(0.0, self.world.noise_std, linear.shape)
        s = self.light.saturation
        exposure = {
            "camera": self.kind,
            "variant": self.variant,
            "spp": self.world.spp,
            "seed": seed,
            "gain": self.light.gain,
            "saturation": s,
            "linearised_gamma": 1.0,
        }
        rotation = None if light_rotation is None else np.asarray(light_rotation, float).reshape(3, 3)
        return Capture(respond(linear, s, self.world.gamma), np.asarray(light_position, float), index, exposure, rotation)

