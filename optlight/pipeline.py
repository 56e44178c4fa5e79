"""The whole job: ``plan = optlight.solve(problem)``, then ``plan.save(folder)``.

A straight line of stages, each taking built objects and returning a typed result (each timed in
``Plan.timings``):

1. ``scene``: :class:`~optlight.setup.Setup` — scene, objectives, robot, limits, environment, built once;
2. ``landmarks``: where the light should go (:func:`~optlight.planning.landmarks.find_landmarks`),
   on the lights whose housing stays out of the camera's view, or the ``[lightset]``'s lights
   designed together (:func:`~optlight.planning.set_landmarks.landmarks_of_set`, captured in a joint-
   space tour); landmarks closer than ``[landmarks] distinct_deg`` are one capture
   (:func:`~optlight.planning.landmarks.distinct_landmarks`);
3. ``placement``: joint angles at every landmark (:func:`~optlight.planning.policy.place_landmarks`:
   IK, a clear posture, or the joint-space placement NLP, which moves a landmark along its azimuth);
4. ``path``: visiting order, great-circle knots, and per-knot IK along the path (the paper's
   pipeline, and the NLP's warm start);
5. ``nlp``: the trajectory NLP over all knots (:func:`~optlight.planning.trajectory.optimize_knots`),
   with the view rows (``[view]``) and clearance rows (``[environment] enabled``); the transfers from
   the start configuration to the first capture and back (``[trajectory] return_home``);
6. ``timing``: per landmark pair, jerk-limited (:mod:`optlight.planning.jerk`, the default) or
   TOPPRA (``[trajectory] timing``), with a dwell at every landmark;
7. ``verify``: dense resampling, independent of the planner (exact coal distances for the
   environment; the jerk and the acceleration continuity at ``[trajectory] rate_hz``; the exact view
   and beam check at the captures, always).
"""

from __future__ import annotations

import time
import warnings
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from functools import partial
from pathlib import Path

import numpy as np

from optlight.environment.view import view_check_for
from optlight.plan import Plan
from optlight.planning.jerk import jerk_limited_timing
from optlight.planning.landmarks import distinct_landmarks, find_landmarks
from optlight.planning.path import build_path
from optlight.planning.policy import knot_ik, place_landmarks, visiting_order
from optlight.planning.set_landmarks import landmarks_of_set, set_summary, tour_order
from optlight.planning.timing import Trajectory, time_parameterize
from optlight.planning.trajectory import optimize_knots, plan_transfer
from optlight.setup import Setup
from optlight.spec import Problem
from optlight.verify import verify_trajectory

#: progress(stage, done, total): called as each stage advances.
Progress = Callable[[str, int, int], None]

STAGES = ("scene", "landmarks", "placement", "path", "nlp", "timing", "verify")


def solve(problem: Problem | Setup | str | Path, *, progress: Progress | None = None) -> Plan:
    """Solve a problem (a :class:`Problem`, a built :class:`Setup`, a file path or a built-in name)
    end to end.

    Raises :class:`UnreachableError` for a landmark the robot cannot reach, :class:`SolverError` when
    the trajectory NLP fails. The plan is returned even when verification fails (so the report can be
    shown); :meth:`Plan.save` refuses to export it.
    """
    notify = progress or (lambda stage, done, total: None)
    timings: dict[str, float] = {}
    t_total = time.perf_counter()

    @contextmanager
    def stage(name: str) -> Iterator[None]:
        start = time.perf_counter()
        notify(name, 0, 1)
        yield
        timings[name] = time.perf_counter() - start
        notify(name, 1, 1)

    with stage("scene"):
        setup = problem if isinstance(problem, Setup) else Setup.from_problem(problem)
    robot, sphere = setup.robot, setup.sphere

    start = time.perf_counter()
    design = None
    if setup.problem.lightset.kind != "none":  # a light set instead of the per-azimuth search
        landmarks, design = landmarks_of_set(setup)
    else:
        landmarks = find_landmarks(setup, progress=lambda d, t: notify("landmarks", d, t))
    captures, merged = distinct_landmarks(landmarks.landmarks, np.deg2rad(setup.landmark_spec.distinct_deg))
    timings["landmarks"] = time.perf_counter() - start

    with stage("placement"):
        placement = place_landmarks(setup, captures)
    notes = [*landmarks.notes, *merged, *placement.warnings]

    with stage("path"):
        order = tour_order(placement.thetas) if design else visiting_order(setup, placement)
        visited = tuple(placement.landmarks[i] for i in order)
        positions = np.array([lm.position for lm in visited])
        landmark_thetas = placement.thetas[order]
        # the NLP's step bound |θ_{k+1} − θ_k|∞ ≤ max_step_rad must leave room to go between postures
        reconfiguration = np.abs(np.diff(landmark_thetas, axis=0)).max(axis=1, initial=0.0)
        path = build_path(
            sphere,
            positions,
            np.arange(len(visited)),
            np.deg2rad(setup.trajectory_spec.knot_spacing_deg),
            min_intervals=np.ceil(2.0 * reconfiguration / setup.trajectory_spec.max_step_rad).astype(int) + 1,
        )
        warm, failures = knot_ik(setup, path, landmark_thetas)
    lightset = set_summary(setup, design, placement.landmarks, placement.thetas, order) if design else None
    if failures:
        notes.append(f"per-knot IK did not converge at {failures} of {path.n_knots} knots (NLP warm start)")

    with stage("nlp"):
        nlp = optimize_knots(setup, path, warm)
        approach = plan_transfer(setup, setup.start, nlp.theta[0])
        retreat = (
            plan_transfer(setup, nlp.theta[-1], setup.start) if setup.trajectory_spec.return_home else None
        )

    with stage("timing"):
        segments = [nlp.theta[s] for s in path.segments()] or [nlp.theta[:1]]  # one landmark: its dwell
        limits, spec = setup.limits, setup.trajectory_spec
        jerk_limited = spec.timing == "jerk_limited"
        timed: Callable[..., Trajectory] = (
            partial(jerk_limited_timing, segments, limits.velocity, limits.acceleration, limits.jerk)
            if jerk_limited
            else partial(time_parameterize, segments, limits.velocity, limits.acceleration)
        )
        trajectory = timed(spec.dwell_s, joint_names=robot.joint_names, approach=approach, retreat=retreat)

    with stage("verify"):
        environment = setup.environment
        report = verify_trajectory(
            trajectory,
            light_pose=robot.light_pose,
            lower=setup.limits.lower,
            upper=setup.limits.upper,
            velocity_limit=setup.limits.velocity,
            acceleration_limit=setup.limits.acceleration,
            sphere=sphere,
            landmark_positions=positions,
            planned_path=np.array([robot.light_pose(t)[0] for t in nlp.theta]),
            environment=(
                (lambda q, t, captures: environment.check(robot, q, t, capture_times=captures))
                if environment is not None
                else None
            ),
            jerk_limit=limits.jerk if jerk_limited else None,
            view=(
                view_check_for(robot, setup.scene, setup.problem.light).check
                if setup.problem.view.mode != "off"
                else None
            ),
            rate_hz=max(1000.0, spec.rate_hz),
        )
    timings["total"] = time.perf_counter() - t_total
    for note in notes:
        warnings.warn(note, stacklevel=2)
    return Plan(
        setup=setup,
        landmarks=landmarks,
        visited=visited,
        landmark_thetas=landmark_thetas,
        path=path,
        knot_ik=warm,
        nlp=nlp,
        trajectory=trajectory,
        verification=report,
        timings=timings,
        warnings=tuple(notes),
        lightset=lightset,
    )
