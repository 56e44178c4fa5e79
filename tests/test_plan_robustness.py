"""Cells the shipped problems do not cover plan and verify, or say why: the light's beam onto the
object is planned around where the camera's view is (placement, set design, the trajectory NLP's
captures)."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import reduced_problem

import optlight
from optlight.environment.view import view_check_for
from optlight.setup import Setup


def _sphere_stereo(zenith_max_deg: float = 50.0) -> optlight.Problem:
    """A photometric-stereo set of 10 lights on a matte sphere, panda, a 50° cap."""
    return reduced_problem(
        "photometric_stereo",
        camera_px=64,
        object={"kind": "sphere", "radius_m": 0.08},
        light_sphere={"zenith_max_deg": zenith_max_deg},
        lightset={"count": 10, "starts": 1},
    )


@pytest.fixture(scope="module")
def stereo_setup() -> Setup:
    return Setup.from_problem(_sphere_stereo())


def test_beam_rows_casadi_and_numpy_agree(stereo_setup: Setup) -> None:
    env, robot = stereo_setup.environment, stereo_setup.robot
    assert env is not None and env.beam is not None
    function = env.view_cone_function(robot)
    labels = env.view_labels(robot)
    assert function.size1_out(0) == len(labels) and any(label.endswith("↔ beam") for label in labels)
    rng = np.random.default_rng(3)
    for theta in robot.random_configuration(rng, 5):
        numpy_rows = env.sphere_clearance(robot, theta)[1]
        np.testing.assert_allclose(np.asarray(function(theta)).ravel(), numpy_rows, atol=1e-9)


def test_beam_cone_holds_every_ray_the_exact_check_casts(stereo_setup: Setup) -> None:
    """Points on the rays from the light to the object's bounding sphere, beyond the housing's radius
    where the ray caster starts, are inside the beam cone (sd < 0); points off every such ray by more
    than the smoothing are outside (sd > 0): brute force by the cone's definition."""
    env = stereo_setup.environment
    assert env is not None and env.beam is not None
    beam, rng = env.beam, np.random.default_rng(0)
    apex = beam.center + np.array([0.1, -0.2, 0.3])
    targets = beam.center + beam.radius * rng.normal(size=(500, 3)) / np.sqrt(3.0) * rng.uniform(0, 1, (500, 1))
    targets = targets[np.linalg.norm(targets - beam.center, axis=1) < beam.radius]
    rays = targets - apex
    length = np.linalg.norm(rays, axis=1)
    s = rng.uniform(beam.skip, length)
    on_rays = apex + (s / length)[:, None] * rays
    on_rays = on_rays[(on_rays - apex) @ (beam.center - apex) / np.linalg.norm(beam.center - apex)
                      <= np.linalg.norm(beam.center - apex)]
    assert (beam.signed_distance(on_rays, apex) < 0).all()
    # far to the side of the beam, and behind the light
    side = apex + np.cross(beam.center - apex, [0.0, 0.0, 1.0]) + rng.normal(scale=0.01, size=(50, 3))
    behind = apex - 0.5 * (beam.center - apex) + rng.normal(scale=0.01, size=(50, 3))
    assert (beam.signed_distance(np.vstack([side, behind]), apex) > 0).all()


def test_a_stereo_set_on_a_sphere_keeps_the_arm_out_of_the_beam() -> None:
    """A photometric-stereo set on a sphere with a 50° cap on the panda: the arm stood in the light's
    beam at some lights (verification failed on the beam) when the beam was only verified."""
    plan = optlight.solve(_sphere_stereo())
    assert plan.verification.passed, plan.verification
    view = view_check_for(plan.setup.robot, plan.setup.scene, plan.setup.problem.light)
    captures = plan.trajectory.capture_times
    report = view.check(plan.trajectory.sample(captures)[0], captures)
    assert len(report.captures) >= 8 and all(c.beam_blocked == 0.0 for c in report.captures)
