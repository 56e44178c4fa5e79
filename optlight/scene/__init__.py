"""The scene: camera, object, G-buffer, and the two luminance models built on it (docs/design.md §4).

:class:`Scene` is what the objectives and the planners use::

    scene = Scene.from_problem(problem, width=64, height=64)
    image = scene.render(scene.sphere.position(0.3, 1.0))
    f = scene.luminance()                      # casadi.Function (a, v) -> I
    I = f(a, scene.visibility(a))

Pixel vectors (P,) follow ``scene.gbuffer.pixel_index`` (row-major object pixels).
"""

from __future__ import annotations

import copy
import dataclasses
from typing import Any

import casadi as ca
import numpy as np
import trimesh
from numpy.typing import ArrayLike, NDArray

from optlight.errors import ProblemError
from optlight.geometry import LightSphere
from optlight.scene.camera import Camera
from optlight.scene.gbuffer import GBuffer, RayCaster, ShadowRays, build_gbuffer
from optlight.scene.luminance import luminance_function
from optlight.scene.objects import SceneObject, build_object
from optlight.scene.render import shade, to_image
from optlight.spec import LightSpec, Problem

Array = NDArray[np.float64]

__all__ = ["Camera", "GBuffer", "Scene", "SceneObject"]

#: Offset of shadow-ray origins along the normal, as a fraction of the mesh's bounding-box diagonal.
SHADOW_EPSILON = 1e-5


class Scene:
    """A problem's camera, light sphere, object (world frame) and G-buffer, built once.

    Attributes: ``problem``, ``camera`` (:class:`Camera`), ``sphere`` (:class:`LightSphere`),
    ``object`` (:class:`SceneObject`), ``mesh`` (trimesh, world frame, m), ``albedo`` (V,) per
    vertex, ``light`` (:class:`LightSpec`), ``gbuffer`` (:class:`GBuffer`).
    """

    def __init__(self, problem: Problem, camera: Camera, obj: SceneObject, caster: RayCaster | None = None) -> None:
        """Check that the object lies inside the light sphere, then cast the primary rays
        (``caster``: the object's ray caster when already built, e.g. by another resolution).

        Raises :class:`ProblemError` with key ``light_sphere.radius_m`` when a vertex is at b or
        farther from O (the light could not circle the object), and key ``camera`` when no pixel
        sees the object.
        """
        self.problem = problem
        self.camera = camera
        self.sphere = LightSphere.from_problem(problem)
        self.object = obj
        self.mesh: trimesh.Trimesh = obj.mesh
        self.albedo: Array = obj.albedo
        self.light: LightSpec = problem.light
        file = str(problem.source) if problem.source else "<inline>"
        extent = float(np.max(np.linalg.norm(obj.mesh.vertices - self.sphere.center, axis=1)))
        if extent >= self.sphere.radius:
            raise ProblemError(
                file,
                "light_sphere.radius_m",
                f"a light sphere around the whole object (radius > {extent:.3f} m, the farthest "
                "object point from object.center_m)",
                self.sphere.radius,
            )
        self._caster = caster if caster is not None else RayCaster(obj.mesh)
        self.gbuffer: GBuffer = build_gbuffer(camera, obj, self._caster)
        if self.gbuffer.size == 0:
            raise ProblemError(
                file,
                "camera",
                "a camera that sees the object (no pixel ray hits it)",
                camera.position.tolist(),
            )
        self._shadows = self._shadow_rays()
        self._luminance: dict[bool, ca.Function] = {}
        #: γ of the camera response s·(I/s)^(1/γ) applied to every rendered value (1: linear); only a
        #: calibrated scene (:meth:`calibrated`) has another.
        self.response_gamma = 1.0

    @classmethod
    def from_problem(cls, problem: Problem, width: int | None = None, height: int | None = None) -> Scene:
        """The scene of a problem (its object built here), optionally at another resolution
        (see :meth:`resampled`). Raises :class:`ProblemError` (key ``camera.look_at_m``) when the
        object centre is not inside the camera's image."""
        camera = Camera.from_spec(problem.camera, problem.object.center_m)
        centre = np.asarray(problem.object.center_m, float)
        u, v, depth = camera.project(centre[None, :])
        if depth[0] <= 0 or not (0 <= u[0] < camera.width and 0 <= v[0] < camera.height):
            target = problem.camera.look_at_m if problem.camera.look_at_m is not None else centre.tolist()
            raise ProblemError(
                str(problem.source) if problem.source else "<inline>",
                "camera.look_at_m",
                "a camera that sees the object centre inside its image",
                list(target),
            )
        scene = cls(problem, camera, build_object(problem))
        return scene if width is None and height is None else scene.resampled(width, height)

    def resampled(self, width: int | None = None, height: int | None = None) -> Scene:
        """The same view and object at another image size; the object and its ray caster are
        shared, only the primary rays are cast again.

        fx, fy scale by W'/W, H'/H and the principal point by c' = (c + ½)·W'/W − ½ (pixel centres
        at integers); a missing side keeps the aspect ratio.
        """
        camera = self.camera
        w0, h0 = camera.width, camera.height
        w = int(width) if width is not None else max(1, round(w0 * int(height or h0) / h0))
        h = int(height) if height is not None else max(1, round(h0 * w / w0))
        sx, sy = w / w0, h / h0
        camera = dataclasses.replace(
            camera,
            fx=camera.fx * sx,
            fy=camera.fy * sy,
            cx=(camera.cx + 0.5) * sx - 0.5,
            cy=(camera.cy + 0.5) * sy - 0.5,
            width=w,
            height=h,
        )
        return Scene(self.problem, camera, self.object, self._caster)

    def visibility(self, light_position: ArrayLike) -> Array:
        """Cast-shadow visibility v (P,) in {0., 1.} for a light at ``light_position`` (world, m),
        or (S, P) for S lights (S, 3), from shadow rays
        (:meth:`optlight.scene.gbuffer.ShadowRays.visibility`); all ones when ``light.cast_shadows``
        is false."""
        if not self.light.cast_shadows:
            return np.ones((*np.shape(light_position)[:-1], self.gbuffer.size))
        return self._shadows.visibility(light_position)

    def _shadow_rays(self) -> ShadowRays:
        """The shadow rays of this scene's G-buffer and light model, their origins offset by
        :data:`SHADOW_EPSILON` times the object's scale."""
        epsilon = SHADOW_EPSILON * float(self.mesh.scale)
        return ShadowRays(self._caster, self.gbuffer, self.light.model, self.sphere.center, epsilon)

    def pixels(
        self,
        light_position: ArrayLike,
        visibility: ArrayLike | None = None,
        noise: bool | np.random.Generator = False,
    ) -> Array:
        """Object pixel values I (P,) from the NumPy renderer (:func:`optlight.scene.render.shade`);
        ``visibility`` None computes it with :meth:`visibility`."""
        v = self.visibility(light_position) if visibility is None else visibility
        value = shade(self.gbuffer, light_position, self.light, self.sphere.center, self.sphere.radius, v, noise)
        return value if self.response_gamma == 1.0 else self._respond(value)

    def render(self, light_position: ArrayLike, noise: bool | np.random.Generator = False) -> Array:
        """The (H, W) image for a light at ``light_position``, background 0, shadows included."""
        return self.to_image(self.pixels(light_position, noise=noise))

    def to_image(self, pixels: ArrayLike) -> Array:
        """The (H, W) image holding ``pixels`` (P,) at the object pixels, 0 elsewhere."""
        return to_image(self.gbuffer, pixels)

    def luminance(self, smooth: bool = True) -> ca.Function:
        """The CasADi Function (a, v) -> I of :func:`optlight.scene.luminance.luminance_function`,
        built on first use and cached per ``smooth``."""
        if smooth not in self._luminance:
            f = luminance_function(self.gbuffer, self.light, self.sphere.center, self.sphere.radius, smooth)
            if self.response_gamma != 1.0:
                a, v = ca.MX.sym("a", 3), ca.MX.sym("v", self.gbuffer.size)
                f = ca.Function("luminance", [a, v], [self._respond(f(a, v))], ["a", "v"], ["I"])
            self._luminance[smooth] = f
        return self._luminance[smooth]

    # ------------------------------------------------------------------------------------------
    # The calibrated model (the camera in the loop, :mod:`optlight.capture.calibration`)
    # ------------------------------------------------------------------------------------------

    def calibrated(
        self,
        light: LightSpec,
        albedo: ArrayLike,
        normals: ArrayLike | None = None,
        response_gamma: float = 1.0,
    ) -> Scene:
        """The same view and object with the light model ``light``, the G-buffer albedo ``albedo``
        (P,), optionally the G-buffer normals (P, 3, unit), and the camera response
        I_cam = s·(I/s)^(1/γ) (γ = ``response_gamma``, s = ``light.saturation``) applied to every
        rendered value (:meth:`pixels`, :meth:`luminance`). Shadow rays still use the mesh.
        :meth:`resampled` of the result starts again from the object's albedo and normals."""
        gb = self.gbuffer
        new_albedo = np.asarray(albedo, float).reshape(gb.size)
        new_normals = gb.normals if normals is None else np.asarray(normals, float).reshape(gb.size, 3)
        scene = copy.copy(self)
        scene.light = light
        scene.gbuffer = dataclasses.replace(gb, albedo=new_albedo, normals=new_normals)
        scene.response_gamma = float(response_gamma)
        scene._luminance = {}
        scene._shadows = scene._shadow_rays()  # the normals and the light model may have changed
        return scene

    def _respond(self, value: Any) -> Any:
        """s·((I/s)₊ + ε)^(1/γ) − s·ε^(1/γ), ε = 1e-12: the response, finite-slope at I = 0 (NumPy or CasADi)."""
        s, k, eps = self.light.saturation, 1.0 / self.response_gamma, 1e-12
        if isinstance(value, np.ndarray):
            return s * ((np.maximum(value / s, 0.0) + eps) ** k - eps**k)
        return s * ((ca.fmax(value / s, 0) + eps) ** k - eps**k)
