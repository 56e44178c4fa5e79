"""The whole job: ``plan = optlight.solve(problem)``, then ``plan.save(folder)``.

Stages (each timed in ``Plan.timings``):

1. ``scene``: camera, object, G-buffer;
2. ``landmarks``: where the light should go (:func:`optlight.planning.landmarks.find_landmarks`);
3. ``placement``: joint angles at every landmark by generalized IK (5-D task, roll free), chained
   from one landmark to the next; where IK cannot reach a landmark, or (``[environment] enabled``)
   its IK solution breaks the clearance or blocks the camera's view, the joint-space placement NLP
   moves it to the best light on its azimuth the robot reaches clear of the environment (with a
   warning); a landmark neither reaches is an error that names it, or is dropped with a warning when
   ``[landmarks] allow_partial`` is set;
4. ``path``: visiting order (azimuth, or a short open tour in joint space), great-circle knots, and
   per-knot IK along the path (the paper's pipeline, and the NLP's warm start);
5. ``nlp``: the trajectory NLP over all knots (:class:`TrajectoryOptimizer`), with clearance and
   view-cone constraints when ``[environment] enabled``;
6. ``timing``: TOPPRA per landmark pair with a dwell at every landmark;
7. ``verify``: dense resampling, independent of the planner (exact coal distances for the
   environment).
"""

from __future__ import annotations

import time
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from optlight.environment import Environment
from optlight.errors import IPOPT_ITERATION_LIMIT, SolverError, UnreachableError, iteration_limit_error
from optlight.geometry import LightSphere
from optlight.planning.landmarks import Landmark, LandmarkSet, find_landmarks
from optlight.planning.path import LightPath, azimuth_order, build_path, shortest_open_tour
from optlight.planning.placement import ClearPosture, LightPlacement
from optlight.planning.timing import Trajectory, time_parameterize
from optlight.planning.trajectory import TrajectoryNLPResult, TrajectoryOptimizer
from optlight.robot import IKResult, Robot, generalized_ik, ik_settings, load_robot
from optlight.scene import Scene
from optlight.spec import Problem, load_problem
from optlight.verify import VerificationReport, verify_trajectory

if TYPE_CHECKING:
    from optlight.viz.preview import Preview

Array = NDArray[np.float64]

#: progress(stage, done, total): called as each stage advances.
Progress = Callable[[str, int, int], None]

STAGES = ("scene", "landmarks", "placement", "path", "nlp", "timing", "verify")

#: Said of a placement NLP that stopped at its iteration limit: it may have needed more, not a reach.
_LIMIT_HINT = " at [solver] max_iter: raise it if the landmark should be reachable"


@dataclass(frozen=True)
class Plan:
    """A solved problem: where the light goes, how the robot gets there, and the proof it is safe.

    ``landmarks`` the landmark search; ``visited`` the landmarks kept, in visiting order;
    ``landmark_thetas`` (M, n) joint angles at them; ``path`` the light's knots; ``knot_ik`` the
    per-knot IK configurations (K, n) (the paper's pipeline); ``nlp`` the optimised knots;
    ``trajectory`` the timed motion; ``verification`` the independent check; ``timings`` seconds per
    stage and ``total``; ``warnings`` what was dropped or degraded.
    """

    problem: Problem
    scene: Scene
    robot: Robot
    landmarks: LandmarkSet
    visited: tuple[Landmark, ...]
    landmark_thetas: Array
    path: LightPath
    knot_ik: Array
    nlp: TrajectoryNLPResult
    trajectory: Trajectory
    verification: VerificationReport
    timings: dict[str, float]
    warnings: tuple[str, ...] = field(default=())

    @property
    def joint_path_length(self) -> float:
        """Σ_k |θ_{k+1} − θ_k| over the optimised knots (rad)."""
        return joint_path_length(self.nlp.theta)

    @property
    def motion_time(self) -> float:
        """Time spent moving (s): the trajectory's duration without the dwells."""
        intervals = self.trajectory.landmark_intervals
        return float(self.trajectory.duration - np.sum(intervals[:, 1] - intervals[:, 0]))

    @property
    def light_directions_camera(self) -> Array:
        """(M, 3) unit vectors from the object to the light at each capture, OpenCV camera frame."""
        positions = np.array([lm.position for lm in self.visited])
        d = (positions - self.scene.sphere.center) / self.scene.sphere.radius
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        return self.scene.camera.to_camera_frame(d)

    def summary(self) -> dict[str, Any]:
        """The key numbers, JSON-safe."""
        return {
            "problem": self.problem.name,
            "robot": self.robot.name,
            "landmarks": len(self.visited),
            "knots": self.path.n_knots,
            "mean_landmark_cost": float(np.mean([lm.cost for lm in self.visited])),
            "nlp_status": self.nlp.status,
            "nlp_iterations": self.nlp.iterations,
            "max_h_residual_m": self.nlp.max_h_residual,
            "joint_path_length_rad": self.joint_path_length,
            "knot_ik_path_length_rad": joint_path_length(self.knot_ik),
            "duration_s": self.trajectory.duration,
            "motion_time_s": self.motion_time,
            "verification_passed": self.verification.passed,
            "min_clearance_m": {
                name: -check.max_value
                for name, check in self.verification.checks.items()
                if name in ("clearance", "self_collision", "view_cone")
            },
            "timings_s": dict(self.timings),
        }

    def preview(self) -> Preview:
        """The Meshcat preview: landmarks coloured by cost, the planned path, the trajectory as an
        animation, the object shaded for the first capture. ``.save_html(path)`` or ``.serve()``."""
        from optlight.viz.preview import Preview

        return Preview(
            self.scene,
            self.robot,
            np.array([lm.position for lm in self.visited]),
            np.array([lm.cost for lm in self.visited]),
            self.path.positions,
            self.trajectory,
            light_position=self.visited[0].position,
        )

    def save(self, folder: str | Path, *, overwrite: bool = False, preview: bool = True) -> list[Path]:
        """Write the results folder (see :func:`optlight.report.save_plan`); refused when the plan
        failed verification. Returns the paths written."""
        from optlight.report import save_plan

        return save_plan(self, folder, overwrite=overwrite, preview=preview)


def joint_path_length(theta: Array) -> float:
    """Σ_k |θ_{k+1} − θ_k| (rad) of a (K, n) knot sequence."""
    return float(np.sum(np.linalg.norm(np.diff(theta, axis=0), axis=1)))


def _ik(
    robot: Robot,
    sphere: LightSphere,
    target: Array,
    theta0: Array,
    problem: Problem,
    *,
    restarts: bool = True,
) -> IKResult:
    """Generalized IK with the problem's ``[solver]`` settings (gains, damping, tolerance)."""
    return generalized_ik(robot, sphere, target, theta0, restarts=restarts, **ik_settings(problem.solver))


def place_landmarks(
    problem: Problem,
    robot: Robot,
    sphere: LightSphere,
    landmarks: Sequence[Landmark],
    *,
    scene: Scene | None = None,
    environment: Environment | None = None,
) -> tuple[list[Landmark], Array, list[str]]:
    """Joint angles at each landmark: IK chained in the given order, retried from θ_ref.

    Where both IK attempts fail, the joint-space placement NLP (:class:`LightPlacement`) runs on the
    landmark's azimuth, warm-started from the attempt with the smaller residual (then from the other
    when that fails): when it succeeds the landmark is replaced by the best light the robot reaches
    on that azimuth, kept off the singular reach boundary (status "placed", its cost; a warning says
    how far it moved and why). The NLP is built on the first such landmark and reused; ``scene`` (the
    problem's, camera resolution) is built from ``problem`` then when not given.

    With ``[environment] enabled`` (``environment``: the problem's, built from it when not given) the
    joint angles must also clear it: every row of :meth:`Environment.sphere_clearance` (the NLPs'
    sphere model: clearance, and the view cone, a landmark being a capture) ≥ 0. The IK does not see
    the environment, but a redundant arm has other postures for the same light: where the IK's
    breaks a row, :class:`ClearPosture` looks for the nearest clear one (the light unchanged), from the
    IK from the previous landmark, then from θ_ref. Where neither has one, the placement NLP, which
    has the rows as constraints, runs from the attempt with the larger clearance: it moves the
    landmark along its azimuth to the best light with a clear posture.

    Returns the landmarks kept, their joint angles (M, n) and warnings. Raises
    :class:`UnreachableError` naming the first landmark neither IK nor the placement reaches (with
    both reasons), unless ``allow_partial``, which drops it with a warning.
    """
    kept, thetas, notes = [], [], []
    placement: LightPlacement | None = None
    posture: ClearPosture | None = None
    if not problem.environment.enabled:
        environment = None
    elif environment is None:
        environment = Environment.from_problem(problem)
    previous = robot.theta_ref
    for lm in landmarks:
        # (IK result, its clearance (m) and blocking row, clear joint angles for the light or None)
        attempts: list[tuple[IKResult, float, str, Array | None]] = []
        for start in (previous, robot.theta_ref):
            result = _ik(robot, sphere, lm.position, start, problem)
            clearance, row, clear = np.inf, "", result.theta if result.success else None
            if environment is not None and result.success:
                clearance, row = environment.worst_sphere_row(robot, result.theta)
                if clearance < 0.0:
                    posture = posture if posture is not None else ClearPosture(problem, robot, environment)
                    found = posture.solve(lm.position, result.theta)
                    clear = found[0] if found is not None else None
            attempts.append((result, clearance, row, clear))
            if clear is not None:
                break
        if clear is not None:
            kept.append(lm)
            thetas.append(clear)
            previous = clear
            continue
        # the placement starts from the better attempt (reached before not; then the larger
        # clearance, or the smaller residual), then from the other
        attempts.sort(key=lambda a: (not a[0].success, -a[1] if a[0].success else a[0].residual))
        result, clearance, row, _ = attempts[0]
        why = (
            f"out of reach of {robot.name}: {result.message}"
            if not result.success
            else f"blocked for {robot.name}: its IK solution brings {row} {-clearance * 1e3:.1f} mm too close, "
            "and no posture near it is clear"
        )
        if placement is None:
            scene = scene if scene is not None else Scene.from_problem(problem)
            placement = LightPlacement(problem, scene, robot, environment=environment)
        placed = placement.solve(lm.azimuth, result.theta)
        if not placed.success and attempts[1:]:
            other = placement.solve(lm.azimuth, attempts[1][0].theta)
            placed = other if other.success else placed
        if placed.success:
            kept.append(
                replace(
                    lm,
                    zenith=placed.zenith,
                    position=placed.position,
                    cost=placed.cost,
                    status="placed",
                    solver_status=placed.status,
                    iterations=lm.iterations + placed.iterations,
                    time_s=lm.time_s + placed.time_s,
                )
            )
            thetas.append(placed.theta)
            previous = placed.theta
            goal = (
                f"to be reachable by {robot.name}"
                if not result.success
                else f"to clear the environment ({row} was {-clearance * 1e3:.1f} mm too close)"
            )
            before, after = f"{np.rad2deg(lm.zenith):.1f}°", f"{np.rad2deg(placed.zenith):.1f}°"
            moved = (
                f"moved from zenith {before} to {after}"
                if before != after
                else f"kept at zenith {before} with the placement's joint angles"
            )
            notes.append(
                f"landmark {lm.index} (azimuth {np.rad2deg(lm.azimuth):.1f}°) {moved} {goal} "
                f"(cost {lm.cost:.3g} -> {placed.cost:.3g}; {placed.message})"
            )
            continue
        clear_of = " clear of the environment" if environment is not None else ""
        where = (
            f"landmark {lm.index} (zenith {np.rad2deg(lm.zenith):.1f}°, azimuth "
            f"{np.rad2deg(lm.azimuth):.1f}°) is {why}; nor is any light on its azimuth{clear_of} within "
            f"zenith {np.rad2deg(sphere.zenith_min):.1f}–{np.rad2deg(sphere.zenith_max):.1f}° "
            f"(placement NLP: {placed.message}{_LIMIT_HINT if placed.status == IPOPT_ITERATION_LIMIT else ''})"
        )
        if not problem.landmarks.allow_partial:
            raise UnreachableError(
                f"{where}; move the robot base ([robot] base_position_m) or set [landmarks] allow_partial = true"
            )
        notes.append(f"dropped {where}")
    if len(kept) < 1:
        raise UnreachableError(f"no landmark is reachable by {robot.name}")
    return kept, np.array(thetas), notes


def visiting_order(problem: Problem, landmarks: Sequence[Landmark], thetas: Array) -> NDArray[np.int64]:
    """Azimuth order, or a short open tour in joint space (``[trajectory] order``)."""
    if problem.trajectory.order == "tour":
        distance = np.linalg.norm(thetas[:, None, :] - thetas[None, :, :], axis=2)
        return shortest_open_tour(distance)
    return azimuth_order([lm.azimuth for lm in landmarks])


def knot_ik(
    problem: Problem, robot: Robot, sphere: LightSphere, path: LightPath, theta_start: Array
) -> tuple[Array, int]:
    """Per-knot generalized IK along the path, each knot started from the previous one (the paper's
    pipeline). Returns the (K, n) angles and the number of knots where IK did not converge."""
    thetas = np.empty((path.n_knots, robot.n))
    previous, failures = theta_start, 0
    for k, position in enumerate(path.positions):
        # no random restarts: a restart lands on another IK branch, a jump the path cannot make
        result = _ik(robot, sphere, position, previous, problem, restarts=False)
        failures += not result.success
        thetas[k] = previous = result.theta
    return thetas, failures


def optimize_knots(
    problem: Problem,
    robot: Robot,
    sphere: LightSphere,
    path: LightPath,
    warm: Array,
    environment: Environment | None,
) -> TrajectoryNLPResult:
    """The trajectory NLP over the path's knots, warm-started at the per-knot IK ``warm``.

    Joint steps are weighed by 1/v_max,j² (the squared time at the velocity limits). With an
    environment the NLP is solved twice: first without it, then with the clearance and view-cone rows
    from that solution (a continuation: the free optimum is smooth and mostly clear, which the
    constrained solve converges from far better than from the per-knot IK); when that fails, from the
    per-knot IK itself. Raises :class:`SolverError` when no solve succeeds.
    """

    def optimizer(environment: Environment | None) -> TrajectoryOptimizer:
        return TrajectoryOptimizer(
            robot,
            path_mode=problem.trajectory.path,
            max_step=problem.trajectory.max_step_rad,
            joint_weights=1.0 / (robot.velocity_limit * problem.robot.velocity_scale) ** 2,
            clearance=environment.clearance_function(robot) if environment else None,
            view=environment.view_cone_function(robot) if environment and environment.view_cone else None,
            view_mode=environment.view_mode if environment else "capture",
            max_iter=problem.solver.max_iter,
            tol=problem.solver.tol,
            verbose=problem.solver.verbose,
        )

    nlp = optimizer(None).solve(path, sphere, warm)
    if environment is not None:
        constrained = optimizer(environment)
        start = nlp.theta if nlp.success else warm
        free_time = nlp.time_s
        nlp = constrained.solve(path, sphere, start)
        if not nlp.success and start is not warm:
            nlp = constrained.solve(path, sphere, warm)
        nlp = replace(nlp, time_s=nlp.time_s + free_time)
    if not nlp.success and nlp.status == IPOPT_ITERATION_LIMIT:
        raise iteration_limit_error("the trajectory NLP", problem.solver.max_iter)
    if not nlp.success:
        raise SolverError(
            f"the trajectory NLP failed ({nlp.status} after {nlp.iterations} iterations, "
            f"max |h| = {nlp.max_h_residual:.2e} m); try a smaller [trajectory] knot_spacing_deg, a "
            'larger max_step_rad or path = "free"'
        )
    return nlp


def solve(problem: Problem | str | Path, *, progress: Progress | None = None) -> Plan:
    """Solve a problem (a :class:`Problem`, a file path or a built-in name) end to end.

    Raises :class:`UnreachableError` for a landmark the robot cannot reach, :class:`SolverError` when
    the trajectory NLP fails. The plan is returned even when verification fails (so the report can be
    shown); :meth:`Plan.save` refuses to export it.
    """
    problem = problem if isinstance(problem, Problem) else load_problem(problem)
    timings: dict[str, float] = {}
    notify = progress or (lambda stage, done, total: None)
    t_total = time.perf_counter()

    def stage(name: str) -> Callable[[], None]:
        start = time.perf_counter()
        notify(name, 0, 1)

        def done() -> None:
            timings[name] = time.perf_counter() - start
            notify(name, 1, 1)

        return done

    done = stage("scene")
    scene = Scene.from_problem(problem)
    robot = load_robot(problem)
    sphere = scene.sphere
    environment = Environment.from_problem(problem) if problem.environment.enabled else None
    done()

    start = time.perf_counter()
    landmarks = find_landmarks(problem, scene, progress=lambda d, t: notify("landmarks", d, t))
    timings["landmarks"] = time.perf_counter() - start

    done = stage("placement")
    kept, thetas, notes = place_landmarks(
        problem, robot, sphere, landmarks.landmarks, scene=scene, environment=environment
    )
    done()

    done = stage("path")
    order = visiting_order(problem, kept, thetas)
    visited = tuple(kept[i] for i in order)
    path = build_path(
        sphere,
        np.array([lm.position for lm in visited]),
        np.arange(len(visited)),
        np.deg2rad(problem.trajectory.knot_spacing_deg),
    )
    warm, failures = knot_ik(problem, robot, sphere, path, thetas[order[0]])
    if failures:
        notes.append(f"per-knot IK did not converge at {failures} of {path.n_knots} knots (NLP warm start)")
    done()

    done = stage("nlp")
    nlp = optimize_knots(problem, robot, sphere, path, warm, environment)
    done()

    done = stage("timing")
    segments = [nlp.theta[s] for s in path.segments()] or [nlp.theta[:1]]  # one landmark: its dwell
    trajectory = time_parameterize(
        segments,
        robot.velocity_limit * problem.robot.velocity_scale,
        robot.acceleration_limit,
        problem.trajectory.dwell_s,
        joint_names=robot.joint_names,
    )
    done()

    done = stage("verify")
    planned = np.array([robot.light_pose(t)[0] for t in nlp.theta])
    report = verify_trajectory(
        trajectory,
        light_pose=robot.light_pose,
        lower=robot.lower,
        upper=robot.upper,
        velocity_limit=robot.velocity_limit * problem.robot.velocity_scale,
        acceleration_limit=robot.acceleration_limit,
        sphere=sphere,
        landmark_positions=np.array([lm.position for lm in visited]),
        planned_path=planned,
        environment=(
            (lambda q, t, captures: environment.check(robot, q, t, capture_times=captures))
            if environment
            else None
        ),
    )
    done()
    timings["total"] = time.perf_counter() - t_total
    for note in notes:
        warnings.warn(note, stacklevel=2)
    return Plan(
        problem=problem,
        scene=scene,
        robot=robot,
        landmarks=landmarks,
        visited=visited,
        landmark_thetas=thetas[order],
        path=path,
        knot_ik=warm,
        nlp=nlp,
        trajectory=trajectory,
        verification=report,
        timings=timings,
        warnings=tuple(notes),
    )
