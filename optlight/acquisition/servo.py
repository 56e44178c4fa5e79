"""The photometric servo (docs/design.md §11): the local loop for one light, ViSP's photometric visual
servoing with the light moving instead of the camera (the package docstring gives the step)."""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np
from numpy.typing import NDArray

from optlight.capture import CaptureCamera
from optlight.errors import OptlightError
from optlight.planning.nlp import sphere_position
from optlight.robot import generalized_ik
from optlight.setup import Setup

Array = NDArray[np.float64]

@dataclass(frozen=True, eq=False)
class ServoResult:
    """The photometric servo's trace: per capture the light ``positions`` (world, m), its ``zenith``
    and ``azimuth`` (rad), the ``measured`` cost and whether the step was ``accepted``; ``final`` the
    index of the best capture."""

    positions: Array
    zenith: Array
    azimuth: Array
    measured: Array
    accepted: NDArray[np.bool_]

    @property
    def final(self) -> int:
        return int(np.argmin(self.measured))


def photometric_servo(
    model: Setup,
    camera: CaptureCamera,
    zenith: float,
    azimuth: float,
    *,
    measure: Setup | None = None,
    steps: int | None = None,
    step_deg: float | None = None,
) -> ServoResult:
    """Servo one light from (``zenith``, ``azimuth``) (rad) on the measured cost (module docstring).

    ``model``: the calibrated setup whose differentiable model gives the image Jacobian; ``measure``:
    the setup whose objective scores the recorded images (default ``model``: the same terms and
    reference). ``steps`` captures (default ``[loop] servo_steps``), first step ``step_deg`` degrees
    (default ``[loop] servo_step_deg``). The robot reaches each light by generalized IK from its last
    configuration; a light it cannot reach counts as a rejected step."""
    spec = model.problem.loop
    steps = spec.servo_steps if steps is None else steps
    step = np.deg2rad(spec.servo_step_deg if step_deg is None else step_deg)
    scene, sphere, robot = model.scene, model.sphere, model.robot
    judge = measure or model
    index = judge.scene.gbuffer.pixel_index
    gradient, jacobian = servo_functions(model)
    lo, hi = sphere.zenith_min, sphere.zenith_max

    def reach(z: float, a: float, start: Array | None) -> tuple[Array, Array] | None:
        ik = generalized_ik(robot, sphere, (z, a), start, restarts=start is None, **model.ik)
        return (ik.theta, robot.light_pose(ik.theta)[0]) if ik.success else None

    first = reach(zenith, azimuth, None)
    if first is None:
        raise OptlightError(
            f"the robot cannot put the light at zenith {np.rad2deg(zenith):.1f}°, azimuth {np.rad2deg(azimuth):.1f}°"
        )
    q, position = first
    capture = camera.capture(position, 0)
    cost = judge.objective.numpy(capture.image.ravel()[index])
    trace = [(position, zenith, azimuth, cost, True)]
    z, a = zenith, azimuth
    for k in range(1, steps):
        g_image = np.asarray(gradient(capture.image.ravel()[index])).ravel()
        jac = np.asarray(jacobian(z, a, scene.visibility(position)))
        g = jac.T @ g_image  # dJ/dθ, dJ/dφ
        d = -np.array([g[0], g[1] / max(np.sin(z) ** 2, 1e-6)])
        norm = np.sqrt(d[0] ** 2 + (np.sin(z) * d[1]) ** 2)
        if not norm > 0:
            break
        z_new = float(np.clip(z + step * d[0] / norm, lo, hi))
        a_new = float(a + step * d[1] / norm)
        reached = reach(z_new, a_new, q)
        if reached is None:
            trace.append((position, z_new, a_new, np.inf, False))
            step /= 2
            continue
        new_capture = camera.capture(reached[1], k)
        new_cost = judge.objective.numpy(new_capture.image.ravel()[index])
        accepted = new_cost < cost
        trace.append((reached[1], z_new, a_new, new_cost, accepted))
        if accepted:
            q, position, capture, cost, z, a = reached[0], reached[1], new_capture, new_cost, z_new, a_new
        else:
            step /= 2
    positions, zen, azi, measured, accepted_flags = zip(*trace, strict=True)
    return ServoResult(
        np.array(positions), np.array(zen), np.array(azi), np.array(measured, float), np.array(accepted_flags)
    )


def servo_functions(model: Setup) -> tuple[ca.Function, ca.Function]:
    """∇_I J (I ↦ P-vector) of the objective, and ∂I/∂(θ, φ) (θ, φ, v ↦ P×2) of the model's
    differentiable luminance (smooth max and clip, the calibrated response)."""
    scene, objective = model.scene, model.objective
    pixels = ca.MX.sym("I", scene.gbuffer.size)
    gradient = ca.Function("grad_J", [pixels], [ca.gradient(objective.casadi(pixels), pixels)])
    zenith, azimuth = ca.MX.sym("zenith"), ca.MX.sym("azimuth")
    v = ca.MX.sym("v", scene.gbuffer.size)
    image = scene.luminance(smooth=True)(sphere_position(model.sphere, zenith, azimuth), v)
    jacobian = ca.Function(
        "dI_dangles", [zenith, azimuth, v], [ca.jacobian(image, ca.vertcat(zenith, azimuth))]
    )
    return gradient, jacobian
