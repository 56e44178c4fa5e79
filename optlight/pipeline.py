"""The whole job: ``plan = optlight.solve(problem)``, then ``plan.save(folder)``.

A straight line of stages, each taking built objects and returning a typed result, each timed in
``Plan.timings`` and heard by the caller's ``on_stage`` listener as it finishes (:mod:`optlight.stages`;
the solve draws nothing and writes nothing):

1. ``scene``: :class:`~optlight.setup.Setup` — scene, objectives, robot, limits, environment, built once
   (not timed when the caller passes it built, as the command line does in its checks; still heard);
   the stages after it take what they use of it: the work cell and the image costs
   (:mod:`optlight.workcell`) and their own spec section;
2. ``landmarks``: where the light should go (:func:`~optlight.planning.landmarks.find_landmarks`),
   on the lights whose housing stays out of the camera's view, or the ``[lightset]``'s lights
   designed together (:func:`~optlight.planning.set_landmarks.landmarks_of_set`, captured in a joint-
   space tour); landmarks closer than ``[landmarks] distinct_deg`` are one capture
   (:func:`~optlight.planning.landmarks.distinct_landmarks`);
3. ``placement``: joint angles at every landmark (:func:`~optlight.planning.policy.place_landmarks`:
   IK, a clear posture, or the joint-space placement NLP, which moves a landmark along its azimuth),
   each placed as the search finds it (:class:`PlacementAhead`): the stage's time is what is left
   of it once the search is done;
4. ``path``: visiting order, great-circle knots, and per-knot IK along the path (the paper's
   pipeline, and the NLP's warm start);
5. ``nlp``: the trajectory NLP (:func:`~optlight.planning.trajectory.optimize_knots`), in windows
   of about :data:`~optlight.planning.trajectory.windows.NLP_WINDOW_KNOTS` knots cut at captures
   (:func:`~optlight.planning.trajectory.windows.optimize_path`), with the view
   rows (``[view]``) and clearance rows (``[environment] enabled``); where it finds no way on the
   sphere, the segments whose arc the per-knot IK could not follow leave it
   (:func:`optimize_window`); where the motion between two knots comes too close to an obstacle
   (or itself), that segment is refined and solved again
   (:func:`~optlight.planning.trajectory.clear_between_knots`); the transfers from the start
   configuration to the first capture and back (``[trajectory] return_home``);
6. ``timing``: per landmark pair, jerk-limited (:mod:`optlight.planning.jerk`, the default) or
   TOPPRA (``[trajectory] timing``), with a dwell at every landmark;
7. ``verify``: the controller waypoints chosen (:func:`~optlight.planning.waypoints.controller_waypoints`),
   then dense resampling, independent of the planner (exact coal distances for the
   environment; the jerk and the acceleration continuity at ``[trajectory] rate_hz``; the exact view
   and beam check at the captures, always; the waypoints' quintic interpolation).
"""

from __future__ import annotations

import queue
import threading
import time
import warnings
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from functools import partial
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from optlight.environment.view import view_check_for
from optlight.errors import CaptureSolverError, OutOfReachError
from optlight.geometry import LightSphere
from optlight.motion import Trajectory
from optlight.plan import Plan
from optlight.planning.flying import exposure_of, flying_timing
from optlight.planning.jerk import jerk_limited_timing
from optlight.planning.landmarks import Landmark, LandmarkSet, distinct_landmarks, find_landmarks
from optlight.planning.lightsets import Grid, SetCost, grid_from_problem, set_cost_from_problem
from optlight.planning.path import LightPath, build_path
from optlight.planning.policy import (
    LandmarkPlacement,
    PlacementChain,
    Reacher,
    knot_ik,
    place_landmarks,
    tour_costs,
    visiting_order,
)
from optlight.planning.set_landmarks import (
    SetDesign,
    SetReplacement,
    landmarks_of_set,
    set_summary,
    tour_order,
)
from optlight.planning.timing import time_parameterize
from optlight.planning.torque_scaling import within_torque_limits
from optlight.planning.trajectory import (
    clear_between_knots,
    follow_planned_path,
    knots_on_arcs,
    plan_transfer,
)
from optlight.planning.trajectory.windows import hardest_capture, optimize_path
from optlight.planning.turns import unwrapped_postures
from optlight.planning.waypoints import Waypoints, controller_waypoints
from optlight.relocation import base_hint
from optlight.setup import Setup
from optlight.spec import LandmarksSpec, Problem, TrajectorySpec
from optlight.spec.sizing import check_trajectory_samples
from optlight.stages import OptimizedPath, Route, StageListener
from optlight.threads import thread_count
from optlight.verify import VerificationReport, verify_trajectory
from optlight.workcell import Workcell

Array = NDArray[np.float64]

#: progress(stage, done, total): called as each stage advances.
Progress = Callable[[str, int, int], None]

STAGES = ("scene", "landmarks", "placement", "path", "nlp", "timing", "verify")


def solve(
    problem: Problem | Setup | str | Path,
    *,
    progress: Progress | None = None,
    on_stage: StageListener | None = None,
) -> Plan:
    """Solve a problem (a :class:`Problem`, a built :class:`Setup`, a file path or a built-in name)
    end to end. ``on_stage(stage, result)`` hears each stage finish, with its typed result
    (:mod:`optlight.stages`): the command line subscribes the figure worker there
    (:class:`~optlight.report.FigureDrafts`), which draws the results folder's figures while the rest
    is solved.

    Raises :class:`UnreachableError` for a landmark the robot cannot reach (naming, when it reaches
    nothing clear or not a required landmark, a base position that would: :func:`~optlight.relocation.base_hint`),
    :class:`SolverError` when the trajectory NLP fails. The plan is returned even when verification fails (so the report can be
    shown); :meth:`Plan.save` refuses to export it.
    """
    notify = progress or (lambda stage, done, total: None)
    heard = on_stage or (lambda stage, result: None)
    timings: dict[str, float] = {}
    t_total = time.perf_counter()

    @contextmanager
    def stage(name: str) -> Iterator[None]:
        start = time.perf_counter()
        notify(name, 0, 1)
        yield
        timings[name] = time.perf_counter() - start
        notify(name, 1, 1)

    if isinstance(problem, Setup):  # built by the caller (the command line, in its checks): not timed here
        setup = problem
    else:
        with stage("scene"):
            setup = Setup.from_problem(problem)
    heard("scene", setup)
    cell, trajectory_spec = setup.workcell, setup.trajectory_spec

    start = time.perf_counter()
    reacher = Reacher(cell, setup.solver, setup.image_costs)
    try:
        with PlacementAhead(reacher, setup.landmark_spec) as ahead:
            landmarks, design, captures, merged = choose_captures(
                setup, lambda d, t: notify("landmarks", d, t), reacher, found=ahead.offer
            )
            timings["landmarks"] = time.perf_counter() - start
            heard("landmarks", landmarks)

            with stage("placement"):  # what is left of it once the search is done
                if design is None:
                    placement = ahead.placement(captures)
                else:
                    placement = place_captures(setup, captures, design, reacher)
    except OutOfReachError as refused:  # the refusal names the base that would reach the cap
        raise OutOfReachError(f"{refused}; {base_hint(setup)}") from None
    heard("placement", placement)
    notes = [*([setup.start_note] if setup.start_note else []), *landmarks.notes, *merged, *placement.warnings]

    with stage("path"):
        order = (
            tour_order(placement.thetas, tour_costs(trajectory_spec, cell.limits, placement.thetas))
            if design is not None
            else visiting_order(trajectory_spec, cell.limits, placement)
        )
        visited = tuple(placement.landmarks[i] for i in order)
        landmark_thetas = unwrapped_postures(cell.robot, placement.thetas[order], cell.start)
        positions = np.array([lm.position for lm in visited])
        path = capture_path(cell.sphere, trajectory_spec, positions, landmark_thetas)
        warm, failures = knot_ik(cell, path, landmark_thetas)
    heard("path", Route(order, visited, landmark_thetas, path, warm, failures))
    if failures.any():
        notes.append(f"per-knot IK did not converge at {failures.sum()} of {path.n_knots} knots (NLP warm start)")

    with stage("nlp"):
        while True:
            try:
                path, warm, nlp = optimize_path(
                    cell,
                    trajectory_spec,
                    setup.solver,
                    path,
                    warm,
                    failures,
                    landmark_thetas,
                    lambda d, t: notify("nlp", d, t),
                )
                clear = clear_between_knots(cell, trajectory_spec, setup.solver, path, warm, nlp, knots_on_path)
                path, warm, nlp = clear.path, clear.warm, clear.nlp
                break
            except CaptureSolverError as error:
                if not setup.landmark_spec.allow_partial or len(visited) < 2:
                    raise
                k = hardest_capture(landmark_thetas, error.first, error.last)
                lm = visited[k]
                notes.append(
                    f"dropped landmark {lm.index} (zenith {np.degrees(lm.zenith):.1f}°, azimuth "
                    f"{np.degrees(lm.azimuth):.1f}°), capture {k} of the visiting order: the trajectory NLP "
                    f"found no way {error}; of its captures this one needs the largest reconfiguration"
                )
                visited = visited[:k] + visited[k + 1 :]
                landmark_thetas = unwrapped_postures(cell.robot, np.delete(landmark_thetas, k, axis=0), cell.start)
                positions = np.array([lm.position for lm in visited])
                path = capture_path(cell.sphere, trajectory_spec, positions, landmark_thetas)
                warm, failures = knot_ik(cell, path, landmark_thetas)
    heard("nlp", OptimizedPath(visited, landmark_thetas, path, warm, nlp))
    lightset = (
        set_summary(cell.sphere, design, visited, landmark_thetas, np.arange(len(visited))) if design else None
    )
    if path.transfers.any():
        joined = ", ".join(f"{s} → {s + 1}" for s in np.flatnonzero(path.transfers))
        notes.append(
            f"the light leaves the sphere between captures {joined} (visiting order): the per-knot IK "
            "could not follow their great-circle arcs (a knot missed, a jump to another IK branch, or a "
            "collision) and the trajectory NLP found no way on the sphere"
        )

    with stage("timing"):
        timed_path, timed_knots = clear.timed_path, clear.timed_knots
        trajectory = time_knots(setup, timed_path, timed_knots)
        dwell = float(np.sum(np.diff(trajectory.landmark_intervals, axis=1)))
        # before it is sampled: its samples must fit in this machine's memory
        check_trajectory_samples(setup.problem, setup.robot.n, trajectory.duration, dwell)
    heard("timing", trajectory)

    with stage("verify"):
        waypoints = controller_waypoints(trajectory, rate_hz=max(1000.0, trajectory_spec.rate_hz))
        report = verify_knots(setup, trajectory, positions, timed_knots, timed_path.transfers, waypoints)
    heard("verify", report)
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
        waypoints=waypoints,
        verification=report,
        timings=timings,
        warnings=tuple(notes),
        lightset=lightset,
        reach=design.reach if design is not None else None,
    )


def choose_captures(
    setup: Setup,
    progress: Callable[[int, int], None] | None = None,
    reacher: Reacher | None = None,
    *,
    found: Callable[[Landmark], None] | None = None,
) -> tuple[LandmarkSet, SetDesign | None, list[Landmark], list[str]]:
    """Where the light should go: the ``[lightset]``'s lights designed together (then the design too),
    or the per-azimuth landmark search on the view-clear lights; then the distinct captures (landmarks
    closer than ``[landmarks] distinct_deg`` are one) and a note per merge. ``reacher``: the setup's,
    when one is built (a set designed over the reachable lights maps them with it). ``found``: told
    each landmark of the search as it is found (:func:`~optlight.planning.landmarks.find_landmarks`;
    a light set's are not)."""
    design = None
    if setup.lightset_spec.kind != "none":
        reacher = reacher or Reacher(setup.workcell, setup.solver, setup.image_costs)
        landmarks, design = landmarks_of_set(
            reacher, setup.lightset_spec, setup.landmark_spec, wanted_lights(setup), setup.file, progress
        )
    else:
        landmarks = find_landmarks(
            setup.workcell,
            setup.image_costs,
            setup.landmark_spec,
            setup.solver,
            setup.file,
            progress=progress,
            found=found,
        )
    captures, merged = distinct_landmarks(landmarks.landmarks, np.deg2rad(setup.landmark_spec.distinct_deg))
    return landmarks, design, captures, merged


def wanted_lights(setup: Setup) -> Grid | SetCost:
    """What the ``[lightset]`` asks for: its grid (kind "grid",
    :func:`~optlight.planning.lightsets.grid_from_problem`) or its set cost on the search scene
    (:func:`~optlight.planning.lightsets.set_cost_from_problem`)."""
    if setup.lightset_spec.kind == "grid":
        return grid_from_problem(setup.problem)
    return set_cost_from_problem(setup.problem, setup.search_scene, setup.search_objective)


def place_captures(
    setup: Setup, captures: Sequence[Landmark], design: SetDesign | None, reacher: Reacher | None = None
) -> LandmarkPlacement:
    """Joint angles at the captures (:func:`~optlight.planning.policy.place_landmarks`); a light set
    replaces a light the robot cannot reach clear by the one that best keeps the set
    (:class:`~optlight.planning.set_landmarks.SetReplacement`). ``reacher``: the setup's, when one
    is built."""
    reacher = reacher or Reacher(setup.workcell, setup.solver, setup.image_costs)
    replacement = (
        SetReplacement(reacher, design, captures, setup.lightset_spec, setup.landmark_spec)
        if design is not None
        else None
    )
    return place_landmarks(reacher, setup.landmark_spec, captures, replacement=replacement)


class PlacementAhead:
    """The placement chain (:class:`~optlight.planning.policy.PlacementChain`) in a thread of its own
    while the landmark search goes on: each landmark is placed as the search finds it (:meth:`offer`),
    its placement needing only the landmarks before it. The search leaves a core partly idle and
    the placement, a chain of IPOPT solves, uses one; most of both runs without the GIL (Embree's
    rays, NumPy's kernels, IPOPT), so on two cores the search and the placement together take
    ~10 % less than one after the other (the search takes longer, the placement left after it
    much less), with the same placement to the bit.

    The chain takes every landmark offered for a capture. :meth:`placement` returns its placement
    when the captures are the landmarks offered, in their order; when some were merged
    (:func:`~optlight.planning.landmarks.distinct_landmarks`, known only once all are found) it
    places the captures again, in the calling thread. Either way the placement is the one
    :func:`~optlight.planning.policy.place_landmarks` gives, and so is an error (an unreachable
    landmark), raised by :meth:`placement`. With one thread (``OMP_NUM_THREADS=1``, as in a batch's
    workers) nothing runs ahead. As a context manager, leaving it stops the thread (after the
    landmark it is placing): a Ctrl-C during the search does not wait for the chain."""

    def __init__(self, reacher: Reacher, spec: LandmarksSpec) -> None:
        self.reacher, self.spec = reacher, spec
        self._chain = PlacementChain(reacher, spec)
        self._offered: list[Landmark] = []
        self._queue: queue.SimpleQueue[Landmark | None] = queue.SimpleQueue()
        self._error: BaseException | None = None
        self._stopped = False
        self._thread: threading.Thread | None = None
        if thread_count() > 1:
            self._thread = threading.Thread(target=self._run, name="optlight_placement", daemon=True)
            self._thread.start()

    def offer(self, landmark: Landmark) -> None:
        """Place ``landmark`` next, in the thread (nothing without one)."""
        if self._thread is not None:
            self._offered.append(landmark)
            self._queue.put(landmark)

    def _run(self) -> None:
        while (landmark := self._queue.get()) is not None:
            if self._error is None and not self._stopped:
                try:
                    self._chain.add(landmark)
                except BaseException as e:  # raised where the caller asks for the placement
                    self._error = e

    def placement(self, captures: Sequence[Landmark]) -> LandmarkPlacement:
        """The placement of ``captures`` (in their order), as :func:`place_landmarks` gives it."""
        self._join()
        ahead = len(captures) == len(self._offered) and all(
            c is o for c, o in zip(captures, self._offered, strict=True)
        )
        if self._thread is None or not ahead:
            return place_landmarks(self.reacher, self.spec, captures)
        if self._error is not None:
            raise self._error
        return self._chain.finish()

    def _join(self) -> None:
        if self._thread is not None and self._thread.is_alive():
            self._queue.put(None)
            self._thread.join()

    def __enter__(self) -> PlacementAhead:
        return self

    def __exit__(self, *exc: object) -> None:
        self._stopped = True
        self._join()


def capture_path(
    sphere: LightSphere, spec: TrajectorySpec, positions: Array, landmark_thetas: Array
) -> LightPath:
    """Great-circle knots on ``sphere`` through the captures ``positions`` (M, 3) (m) in their
    visiting order, at ``spec.knot_spacing_deg`` (``[trajectory]``); between two captures whose
    postures ``landmark_thetas`` (M, n) differ by Δ (rad, largest joint), at least
    ⌈2Δ / max_step_rad⌉ + 1 intervals, so that the NLP's step bound |θ_{k+1} − θ_k|∞ ≤ max_step_rad
    leaves room to go between the postures."""
    reconfiguration = np.abs(np.diff(landmark_thetas, axis=0)).max(axis=1, initial=0.0)
    return build_path(
        sphere,
        positions,
        np.arange(len(positions)),
        np.deg2rad(spec.knot_spacing_deg),
        min_intervals=np.ceil(2.0 * reconfiguration / spec.max_step_rad).astype(int) + 1,
    )


def knots_on_path(cell: Workcell, path: LightPath, theta: Array) -> tuple[LightPath, Array]:
    """The path and its knots ``theta`` (K, n) (rad) of ``cell``'s robot with knots added on the
    great-circle arcs of the segments on the sphere where two knots' lights are far apart
    (:func:`~optlight.planning.trajectory.knots_on_arcs`): the planned path the timing follows and
    the verification measures against. The added knots' directions, positions and rotations are
    their lights' (as are those of the other knots of their segment); the transfers' are kept."""
    segments = path.segments()
    refined = [theta[s] if off else knots_on_arcs(cell, theta[s]) for s, off in zip(segments, path.transfers, strict=True)]
    if sum(len(k) for k in refined) == sum(s.stop - s.start for s in segments):
        return path, theta
    knots, directions, positions, rotations = [theta[:1]], [path.directions[:1]], [path.positions[:1]], [path.rotations[:1]]
    for s, off, part in zip(segments, path.transfers, refined, strict=True):
        if off:
            poses = (path.directions[s], path.positions[s], path.rotations[s])
        else:
            a, r = zip(*(cell.robot.light_pose(q) for q in part), strict=True)
            a_arr = np.array(a)
            d = a_arr - cell.sphere.center
            poses = (d / np.linalg.norm(d, axis=1, keepdims=True), a_arr, np.array(r))
        knots.append(part[1:])
        for out, values in zip((directions, positions, rotations), poses, strict=True):
            out.append(values[1:])
    landmark_knots = np.concatenate([[0], np.cumsum([len(k) - 1 for k in refined])]).astype(np.int64)
    refined_path = LightPath(
        np.vstack(directions), np.vstack(positions), np.concatenate(rotations), path.order, landmark_knots, path.transfers
    )
    return refined_path, np.vstack(knots)


def time_knots(setup: Setup, path: LightPath, theta: Array) -> Trajectory:
    """The timed trajectory through the knots ``theta`` (K, n) (rad) of ``path``: the transfer from the
    start configuration to the first capture and back (``[trajectory] return_home``; back the way it
    came when the direct way fails, shortened by the transfer NLP), then per
    landmark pair jerk-limited (the default) or TOPPRA (``[trajectory] timing``) profiles, with a
    dwell of ``dwell_s`` at every landmark (``[trajectory] capture = "flying"``: one jerk-limited motion
    through the landmarks at their blur-limited speeds, :func:`~optlight.planning.flying.flying_timing`); each segment's spline within the joint limits and, on the
    sphere, within :data:`~optlight.planning.trajectory.PATH_DEVIATION_M` of the planned path
    (:func:`~optlight.planning.trajectory.follow_planned_path`); the whole motion slowed where its
    joint torques would exceed the robot's limits
    (:func:`~optlight.planning.torque_scaling.within_torque_limits`)."""
    spec, cell, limits = setup.trajectory_spec, setup.workcell, setup.limits
    approach = plan_transfer(cell, setup.solver, cell.start, theta[0])
    retreat = (
        plan_transfer(
            cell, setup.solver, theta[-1], cell.start, detour=np.vstack([theta[::-1], approach[::-1]])
        )
        if spec.return_home
        else None
    )
    segments = [
        theta[s] if off else follow_planned_path(cell, theta[s])
        for s, off in zip(path.segments(), path.transfers, strict=True)
    ] or [theta[:1]]  # one landmark: its dwell

    def timed(scale: float) -> Trajectory:
        """The motion timed with the limits scaled for the torques (planning/torque_scaling.py)."""
        v, a, j = np.sqrt(scale) * limits.velocity, scale * limits.acceleration, scale**1.5 * limits.jerk
        if spec.capture == "flying":
            return flying_timing(
                segments,
                v,
                a,
                j,
                light_positions=setup.robot.light_positions,
                center=setup.sphere.center,
                exposure=exposure_of(spec),
                joint_names=setup.robot.joint_names,
                approach=approach,
                retreat=retreat,
                position_bounds=(limits.lower, limits.upper),
            )
        timing: Callable[..., Trajectory] = (
            partial(jerk_limited_timing, segments, v, a, j)
            if spec.timing == "jerk_limited"
            else partial(time_parameterize, segments, v, a)
        )
        return timing(
            spec.dwell_s,
            joint_names=setup.robot.joint_names,
            approach=approach,
            retreat=retreat,
            position_bounds=(limits.lower, limits.upper),
        )

    return within_torque_limits(timed, setup.dynamics)


def verify_knots(
    setup: Setup,
    trajectory: Trajectory,
    positions: Array,
    theta: Array,
    transfers: NDArray[np.bool_],
    waypoints: Waypoints | None = None,
) -> VerificationReport:
    """Verify ``trajectory`` independently of the planner, at max(1 kHz, ``rate_hz``): limits (jerk
    and acceleration continuity when jerk-limited), h and aim at the captures ``positions`` (M, 3)
    (m), deviation from the path of the knots ``theta`` (K, n) except on the ``transfers`` (M − 1,),
    where the light must stay outside the sphere, the environment by exact coal distances, the
    camera's view and the beam by exact ray casting at the captures, the joint torques (the lamp
    included) against the robot's torque limits, the blur of every exposure, and the quintic interpolation of the controller
    ``waypoints`` (joint_trajectory.yaml's points) against the trajectory."""
    robot, limits, spec, environment = setup.robot, setup.limits, setup.trajectory_spec, setup.environment
    return verify_trajectory(
        trajectory,
        light_pose=robot.light_pose,
        lower=limits.lower,
        upper=limits.upper,
        velocity_limit=limits.velocity,
        acceleration_limit=limits.acceleration,
        sphere=setup.sphere,
        landmark_positions=positions,
        planned_path=robot.light_positions(theta),
        transfers=transfers,
        environment=(
            (lambda q, t, captures: environment.check(robot, q, t, capture_times=captures))
            if environment is not None
            else None
        ),
        jerk_limit=limits.jerk if spec.timing == "jerk_limited" else None,
        view=(
            view_check_for(robot, setup.scene, setup.problem.light).check
            if setup.problem.view.mode != "off"
            else None
        ),
        waypoints=waypoints,
        dynamics=setup.dynamics,
        exposure=exposure_of(spec),
        exposure_windows=trajectory.exposure_windows(spec.settle_s, spec.exposure_s),
        rate_hz=max(1000.0, spec.rate_hz),
    )
