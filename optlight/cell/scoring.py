"""A placement's score, run on the workers: how many of the lights the robot reaches with a clear
view and beam there."""

from __future__ import annotations

import time
from collections import Counter
from typing import Any

import numpy as np

from optlight.cell.spec import Array
from optlight.engine import error_text
from optlight.environment.view import HOUSING, view_check_for
from optlight.planning.landmarks import find_landmarks
from optlight.planning.policy import Reacher
from optlight.setup import Setup
from optlight.spec import Problem


def landmark_lights(problem: Problem) -> Array:
    """(N, 2) zenith, azimuth (rad) of the problem's landmarks."""
    setup = Setup.from_problem(problem)
    landmarks = find_landmarks(
        setup.workcell, setup.image_costs, setup.landmark_spec, setup.solver, setup.file
    )
    return np.column_stack([landmarks.zeniths, landmarks.azimuths])


def evaluate_placement(problem: Problem, lights: Array) -> dict[str, Any]:
    """The score of one placement (module docstring): how many of ``lights`` (N, 2: zenith, azimuth
    in rad) the robot ``reached``, how many of those with the view and the beam ``clear``, how many
    where no robot link blocks a ray (``robot_clear``: only the light's own housing may, which no
    placement changes) and where the housing blocks the view (``housing_blocked``), for each body
    that is the first obstacle of some view or beam ray the number of lights where it is
    (``blocked_by``, most first), ``error`` when the problem cannot be built or the evaluation
    failed (then all counts are 0), and the evaluation's ``time_s``."""
    start = time.perf_counter()
    out: dict[str, Any] = {**unscored(len(lights)), "error": None}
    try:
        setup = Setup.from_problem(problem)
        reacher, robot = Reacher(setup.workcell, setup.solver, setup.image_costs), setup.robot
        thetas = []
        previous = robot.theta_ref
        for zenith, azimuth in lights[np.argsort(lights[:, 1], kind="stable")]:
            position = setup.sphere.position(zenith, azimuth)
            attempt = reacher.attempt(position, previous)
            if attempt.theta is None and previous is not robot.theta_ref:
                attempt = reacher.attempt(position, robot.theta_ref)
            if attempt.theta is not None:
                thetas.append(attempt.theta)
                previous = attempt.theta
        out["reached"] = len(thetas)
        if thetas:
            view = view_check_for(robot, setup.scene, problem.light).check(
                np.array(thetas), np.zeros(len(thetas))
            )
            out["clear"] = sum(c.view_blocked == 0.0 and c.beam_blocked == 0.0 for c in view.captures)
            out["robot_clear"] = sum(
                not ({*c.view_bodies, *c.beam_bodies} - {HOUSING}) for c in view.captures
            )
            out["housing_blocked"] = sum(HOUSING in c.view_bodies for c in view.captures)
            blockers = Counter(b for c in view.captures for b in {*c.view_bodies, *c.beam_bodies})
            out["blocked_by"] = dict(blockers.most_common())
    except Exception as e:  # a placement's failure is its score (0), not the search's end
        out.update(unscored(len(lights)), error=error_text(e))
    out["time_s"] = time.perf_counter() - start
    return out


def unscored(lights: int) -> dict[str, Any]:
    """The counts of a placement that could not be scored."""
    return {
        "lights": lights,
        "reached": 0,
        "clear": 0,
        "robot_clear": 0,
        "housing_blocked": 0,
        "blocked_by": {},
    }
