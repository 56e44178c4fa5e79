"""The camera in the loop (docs/design.md §11): plan, capture, calibrate, re-plan, round after round
until a round no longer improves (the package docstring gives the steps)."""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from optlight.acquisition.measures import improves, measured_costs, modelled_costs, round_measure
from optlight.acquisition.result import Acquisition, Iteration
from optlight.acquisition.rounds import AWAITING, RoundFolders, round_setup
from optlight.capture import Array, Capture, CaptureCamera, ModelCamera
from optlight.capture.calibration import calibrate, calibrated_setup
from optlight.capture.folder import MissingCaptureError
from optlight.errors import OptlightError, VerificationError
from optlight.pipeline import solve
from optlight.plan import Plan
from optlight.robot import Robot
from optlight.setup import Setup
from optlight.spec import Problem

#: Camera kinds :func:`make_camera` builds.
CAMERAS = ("model", "mitsuba", "folder")


#: progress(iteration, stage, done, total): the loop's stage ("plan: <solve stage>", "capture",
#: "calibrate") in the iteration (0-based).
LoopProgress = Callable[[int, str, int, int], None]


def make_camera(kind: str, setup: Setup, folder: str | Path | None = None) -> CaptureCamera | RoundFolders:
    """The camera of ``kind`` for ``setup``: the model or Mitsuba camera in the problem's ``[world]``,
    or the folder camera of an acquisition in rounds in ``folder`` (:class:`RoundFolders`; a single
    folder of images: :class:`FolderCamera` directly)."""
    if kind == "model":
        return ModelCamera(setup.scene, setup.problem.world)
    if kind == "mitsuba":
        from optlight.capture.mitsuba import MitsubaCamera

        return MitsubaCamera(setup.scene, setup.problem.world, file=setup.file)
    if kind == "folder":
        if folder is None:
            raise OptlightError("the folder camera needs the acquisition folder (--out DIR)")
        return RoundFolders(folder, setup.problem)
    raise OptlightError(f"unknown camera {kind!r} (one of {', '.join(CAMERAS)})")


def execute(plan: Plan, camera: CaptureCamera, robot: Robot | None = None) -> list[Capture]:
    """The simulated robot runs ``plan``'s trajectory; one capture per dwell at its trigger time, with
    the nominal light frame where forward kinematics of ``robot`` (default the plan's) puts it (module
    docstring, step 2). The loop passes the problem's robot: a plan on a calibrated lamp moves the
    robot with the lamp's estimated frame, while the camera's world places the real lamp relative to
    the nominal one."""
    nominal = plan.robot if robot is None else robot
    captures = []
    for k, q in enumerate(trigger_joints(plan)):
        position, rotation = nominal.light_pose(q)
        if camera.kind == "folder":
            # its image is the row of the light position the plan wrote into captures.csv (the plan's
            # light frame); the capture keeps the nominal frame's pose, as the simulated ones do
            found = camera.capture(plan.robot.light_pose(q)[0], k, rotation)
            captures.append(dataclasses.replace(found, light_position=position))
        else:
            captures.append(camera.capture(position, k, rotation))
    return captures


def trigger_joints(plan: Plan) -> Array:
    """The joint angles (K, n) at ``plan``'s capture triggers (:meth:`~optlight.motion.Trajectory.trigger_times`:
    after a stop, dwell start + ``settle_s``; on the fly, the instant the light is at the landmark)."""
    trajectory = plan.trajectory
    trigger = trajectory.trigger_times(plan.problem.trajectory.settle_s)
    return np.asarray(trajectory.sample(trigger)[0], float)


def acquire(
    problem: Problem | Setup | str | Path,
    camera: CaptureCamera | RoundFolders | str = "model",
    *,
    folder: str | Path | None = None,
    progress: LoopProgress | None = None,
) -> Acquisition:
    """Run the camera in the loop on ``problem`` (module docstring) with ``camera`` (a
    :class:`~optlight.capture.CaptureCamera`, :class:`RoundFolders` or one of :data:`CAMERAS`;
    ``folder``, the acquisition folder, for "folder").

    With the folder camera each plan names its images for its round (:func:`round_pattern`), and the
    loop stops with status :data:`AWAITING` at the first round whose images are not there, that
    round's plan the ``next_plan``.

    Raises :class:`VerificationError` when the first plan fails verification (the robot never runs
    it; a re-plan that fails ends the loop, like one that fails to solve, and the best plan so far
    stands), :class:`OptlightError` when a round's images were taken for another plan than the one
    planned again for it, and what :func:`optlight.solve` and the cameras raise."""
    notify: LoopProgress = progress or (lambda it, stage, done, total: None)
    setup = problem if isinstance(problem, Setup) else Setup.from_problem(problem)
    device = make_camera(camera, setup, folder) if isinstance(camera, str) else camera
    spec = setup.problem.loop
    model = setup
    pool: list[Capture] = []
    rounds: list[Iteration] = []
    status, next_plan, best = "iteration limit", None, np.inf
    for i in range(spec.iterations):
        start = time.perf_counter()
        plan, failure = _round_plan(model, device, i, notify)
        if plan is None:
            status = failure
            break
        notify(i, "capture", 0, len(plan.visited))
        captures = _round_captures(plan, device, i, setup.robot)
        if captures is None:
            status, next_plan = AWAITING, plan
            break
        notify(i, "capture", len(captures), len(captures))
        pool += captures
        rounds.append(_iteration(i, setup, model, plan, captures, pool, start, notify))
        cost = rounds[-1].score
        if i > 0 and not improves(cost, best, spec.tolerance):
            status = "stopped improving"
            break
        best = min(best, cost)
        calibration = rounds[-1].calibration
        if calibration is None:
            status = "calibration failed"
            break
        model = calibrated_setup(setup, calibration, spec.normals)
    exposure = dict(rounds[0].captures[0].exposure) if rounds and rounds[0].captures else {}
    return Acquisition(setup, device.kind, tuple(rounds), status, next_plan, exposure)


def _round_plan(
    model: Setup, device: CaptureCamera | RoundFolders, i: int, notify: LoopProgress
) -> tuple[Plan | None, str]:
    """Round ``i``'s plan on ``model`` (its images named for the round with the folder camera), or None
    and why the loop stops: a re-plan that fails to solve or fails verification (round 0's failure is
    raised: the robot never runs it)."""
    try:
        plan = solve(round_setup(model, i) if device.kind == "folder" else model, progress=_stage_progress(notify, i))
    except OptlightError as e:
        if i == 0:
            raise
        return None, f"re-plan failed ({e})"
    if not plan.verification.passed:
        if i == 0:
            raise VerificationError(
                f"iteration {i}: the plan failed verification; the robot does not run it\n"
                f"{plan.verification.summary()}",
                plan.verification,
            )
        failed = ", ".join(name for name, check in plan.verification.checks.items() if not check.passed)
        return None, f"re-plan failed verification ({failed}); the robot does not run it"
    return plan, ""


def _round_captures(
    plan: Plan, device: CaptureCamera | RoundFolders, i: int, robot: Robot
) -> list[Capture] | None:
    """The captures of round ``i``'s plan with the nominal light frames of ``robot``, or None when its
    images are not there yet (the round awaits them). Images of a round that do not match its plan
    again are an error."""
    current = device.camera(i) if isinstance(device, RoundFolders) else device
    if current is None:
        return None
    try:
        return execute(plan, current, robot)
    except MissingCaptureError as e:
        if isinstance(device, RoundFolders):
            raise OptlightError(
                f"{e}: round {i}'s images were taken for another plan than the one planned again for it "
                "(the problem file, or an earlier round's images, changed since)"
            ) from None
        if i == 0:
            raise
        return None


def _iteration(
    i: int,
    setup: Setup,
    model: Setup,
    plan: Plan,
    captures: list[Capture],
    pool: list[Capture],
    start: float,
    notify: LoopProgress,
) -> Iteration:
    """Round ``i`` judged and calibrated: its measured and modelled costs, the calibration from every
    usable capture so far (``pool``; None and why when it fails) and the round's measure."""
    measured = measured_costs(setup, captures)
    # where the model believes the lights were: its (calibrated) light frame at the same joints
    modelled = modelled_costs(model, plan.robot.light_positions(trigger_joints(plan)))
    notify(i, "calibrate", 0, 1)
    calibration, error = None, None
    try:
        calibration = calibrate(setup.scene, pool, setup.problem.loop)
    except OptlightError as e:
        error = str(e)
    notify(i, "calibrate", 1, 1)
    measure = None if setup.problem.lightset.kind == "none" else round_measure(setup, plan, captures, calibration)
    return Iteration(
        i,
        plan,
        tuple(captures),
        measured,
        modelled,
        calibration,
        time.perf_counter() - start,
        error,
        measure,
    )


def _stage_progress(notify: LoopProgress, iteration: int) -> Callable[[str, int, int], None]:
    """:func:`optlight.solve`'s progress as the loop's, for one iteration."""
    return lambda stage, done, total: notify(iteration, f"plan: {stage}", done, total)
