"""The camera in the loop (docs/design.md §11): plan, capture, calibrate, re-plan; the photometric servo; the
dataset folder.

:func:`acquire` runs the loop::

    acquisition = optlight.acquire("default", camera="mitsuba")
    acquisition.save("datasets/face")

1. plan on the model (:func:`optlight.solve`: landmarks, placement, trajectory, verification);
2. a simulated robot executes the verified trajectory: at each capture's trigger (the dwell's start
   plus ``[trajectory] settle_s``) the joint angles are the trajectory's, and the light is where
   pinocchio's forward kinematics puts it (``plan.robot.light_pose``); the camera captures there;
3. the *measured* cost of the plan is the mean over its captures of the problem's objective on the
   recorded images (``setup.objective``, never the model that planned); the *modelled* cost the
   same objective on the planning model's images at the same light positions;
4. the model is calibrated from every usable capture so far (:func:`~optlight.capture.calibration.calibrate`)
   and the next plan made on the calibrated model (:func:`~optlight.capture.calibration.calibrated_setup`),
   through the same :func:`optlight.solve`;
5. the loop stops after ``[loop] iterations`` plans, as soon as a plan's measure is not at
   least ``[loop] tolerance`` (relative) below the best so far, or when a re-plan fails to solve or
   fails verification (the reason is the status; the first plan's is raised). The best plan by its
   measure, by the same rule (a later round replaces it only at least ``tolerance`` below), is the
   result; the first plan is the open loop's.

The measure follows the task (:func:`round_measure`, :data:`MEASURES`): landmarks, the measured cost;
a light set, the set's own measure (photometric stereo: the normal error of the normals recovered
from the recorded images against the model's; RTI: the covering radius of the captured lights; a
grid: the angle from its directions to the lights captured for them). Lower is better for each.

With a real camera (the folder camera) the loop runs in rounds, one run of the command per round
(:class:`RoundFolders`; the user's procedure is docs/camera-loop.md). Round i's plan is written to
``round_ii/`` in the acquisition folder (its trajectory.csv, joint_trajectory.yaml and captures.csv
with the trigger times), its images named ``rii_000.png`` … (:func:`round_pattern`, distinct across
rounds); the user runs the robot, saves the images there and runs the command again. That run replays
the loop: it plans round 0 again (the same problem gives the same plan), takes round 0's images,
calibrates, plans round 1 on that calibration (the same images give the same plan) and so on, each
plan checked against the captures.csv written for it, until the first round without images: it
stops with status ``awaiting captures`` and writes that round's folder. Earlier rounds' folders are
written again as they were, never the user's images.

:func:`photometric_servo` is the local loop for one light: ViSP's photometric visual servoing with
the light moving instead of the camera. The error is the measured cost J(Y) of the recorded image;
its gradient along the light sphere is the chain rule through the calibrated differentiable model,
∇_{θ,φ} J = (∂I/∂(θ, φ))ᵀ ∇_I J(Y): the image Jacobian (the interaction matrix) from the model, the
error from the measurement. The light steps by ``servo_step_deg`` against the Riemannian gradient
(metric dθ² + sin²θ dφ²), the robot reaches the new light by IK, the camera captures; a step that does
not lower the measured cost is undone and halved.
"""

from __future__ import annotations

import dataclasses
import json
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import casadi as ca
import numpy as np
from numpy.typing import ArrayLike, NDArray

from optlight.capture import Capture, CaptureCamera, ModelCamera, write_capture_png
from optlight.capture.calibration import Calibration, calibrate, calibrated_setup
from optlight.capture.folder import FolderCamera, MissingCaptureError, read_captures_csv
from optlight.errors import OptlightError, UsageError, VerificationError
from optlight.export import (
    LIGHT_DIRECTION_COLUMNS,
    LIGHT_FRAME,
    MANIFEST,
    library_versions,
    lp_direction,
    lp_text,
    write_captures,
    write_folder,
)
from optlight.jsondata import json_safe
from optlight.photometric_stereo import gbuffer_normal_map, recover_from_scene
from optlight.pipeline import solve
from optlight.plan import Plan
from optlight.planning.lightsets import Cap, coverage
from optlight.planning.nlp import sphere_position
from optlight.robot import generalized_ik
from optlight.scene import Camera
from optlight.setup import Setup
from optlight.spec import Problem
from optlight.spec.sizing import image_names

if TYPE_CHECKING:
    from matplotlib.figure import Figure

Array = NDArray[np.float64]

#: Camera kinds :func:`make_camera` builds.
CAMERAS = ("model", "mitsuba", "folder")
#: progress(iteration, stage, done, total): the loop's stage ("plan: <solve stage>", "capture",
#: "calibrate") in the iteration (0-based).
LoopProgress = Callable[[int, str, int, int], None]
#: The kind of output in rounds (:mod:`optlight.export`'s manifest) of an acquisition with the folder
#: camera: the same command continues it.
ROUNDS = "optlight acquire --camera folder"
#: Status of a loop that waits for the images of its next round.
AWAITING = "awaiting captures"


def round_folder(index: int) -> str:
    """The folder of round ``index`` (0: the open loop's plan) in an acquisition folder: ``round_00`` …."""
    return f"round_{index:02d}"


def round_pattern(index: int) -> str:
    """The image names of round ``index``: ``r00_000.png`` …, distinct across rounds."""
    return f"r{index:02d}_{{index:03d}}.png"


def round_setup(setup: Setup, index: int) -> Setup:
    """``setup`` whose exports name the images of round ``index`` (:func:`round_pattern`)."""
    problem = setup.problem
    trajectory = dataclasses.replace(problem.trajectory, image_pattern=round_pattern(index))
    return dataclasses.replace(setup, problem=dataclasses.replace(problem, trajectory=trajectory))


class RoundFolders:
    """The folder camera of an acquisition in rounds (module docstring): round i's captures.csv in
    ``folder/round_ii/`` and its images beside it.

    Made before any work, it checks what is there: the rounds whose images are there, in order, each
    with every check of :class:`FolderCamera` (one row per image, distinct lights, no missing file,
    the camera's size); the first round folder without any of its images is the one awaiting
    captures. An acquisition of another problem in ``folder`` is refused."""

    kind = "folder"

    def __init__(self, folder: str | Path, problem: Problem) -> None:
        self.folder = Path(folder)
        _check_same_problem(self.folder, problem)
        camera = Camera.from_spec(problem.camera, problem.object.center_m)
        self.cameras: list[FolderCamera] = []
        while True:
            sub = self.folder / round_folder(len(self.cameras))
            if not (sub / "captures.csv").is_file():
                break
            names, _ = read_captures_csv(sub / "captures.csv")
            if not any((sub / name).is_file() for name in names):
                break  # the round awaiting captures
            self.cameras.append(FolderCamera(sub, camera, problem.light.saturation))

    def camera(self, index: int) -> FolderCamera | None:
        """The camera of round ``index``, None when its images are not there yet."""
        return self.cameras[index] if index < len(self.cameras) else None


def _check_same_problem(folder: Path, problem: Problem) -> None:
    """Refuse to continue an acquisition ``folder`` begun with another problem definition."""
    try:
        document = json.loads((folder / "acquisition.json").read_text())
    except (OSError, ValueError):
        return  # nothing begun there
    before = document.get("problem_definition") if isinstance(document, dict) else None
    if before is not None and before != json.loads(json.dumps(json_safe(problem.to_dict()))):
        raise UsageError(
            "--out",
            f"{folder} holds an acquisition of another problem definition ({document.get('problem')}): "
            "continue it with the problem file as it was, or give a new folder",
        )


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


def execute(plan: Plan, camera: CaptureCamera) -> list[Capture]:
    """The simulated robot runs ``plan``'s trajectory; one capture per dwell at its trigger time, with
    the light where forward kinematics puts it (module docstring, step 2)."""
    trajectory = plan.trajectory
    trigger = trajectory.landmark_intervals[:, 0] + plan.problem.trajectory.settle_s
    joints = trajectory.sample(trigger)[0]
    return [camera.capture(plan.robot.light_pose(q)[0], k) for k, q in enumerate(joints)]


def measured_costs(setup: Setup, captures: Sequence[Capture]) -> Array:
    """The problem's objective (``setup.objective``, camera resolution) on each recorded image."""
    index = setup.scene.gbuffer.pixel_index
    return np.array([setup.objective.numpy(c.image.ravel()[index]) for c in captures])


def modelled_costs(model: Setup, positions: ArrayLike) -> Array:
    """The objective on ``model``'s own images (NumPy renderer, shadow rays) at light ``positions``."""
    return np.array([model.objective.numpy(model.scene.pixels(a)) for a in np.asarray(positions, float)])


#: What the loop judges a round by, per ``[lightset] kind`` (:func:`round_measure`); lower is better.
MEASURES = {
    "none": "measured cost",
    "photometric_stereo": "photometric-stereo normal error (deg)",
    "rti": "RTI covering radius (deg)",
    "grid": "grid angular error (deg)",
}


def round_measure(setup: Setup, plan: Plan, captures: Sequence[Capture], calibration: Calibration | None) -> float:
    """The measure of a round (:data:`MEASURES`, by ``[lightset] kind``; lower is better):

    - no light set: the mean over the captures of the problem's objective on the recorded images;
    - photometric_stereo: the mean over the object's pixels of the angle (deg) between the normal
      photometric stereo recovers from the recorded images and the model's (G-buffer) normal, 90°
      where it recovers none (fewer than three usable lights): the images linearised by the
      ``calibration``'s response γ, its ambient image subtracted, its light power as the lights'
      strength, the lights where the robot put them (directions from the object's centre, the
      directional model; :func:`~optlight.photometric_stereo.recover_from_scene`);
    - rti: the covering radius (deg) of the captured lights on the allowed cap (every point of the
      cap within it of a light; :func:`~optlight.planning.lightsets.coverage`);
    - grid: the largest angle (deg) between a grid direction and the light captured for it (the
      plan's grid report: the captures are at the plan's lights)."""
    spec = setup.problem.lightset
    if spec.kind == "none":
        return float(np.mean(measured_costs(setup, captures)))
    if spec.kind == "grid":
        return float((plan.lightset or {}).get("grid", {}).get("max_moved_deg", 0.0))
    sphere = setup.sphere
    d = np.array([c.light_position for c in captures]) - sphere.center
    directions = (d / np.linalg.norm(d, axis=1, keepdims=True)) @ sphere.rotation  # sphere frame
    if spec.kind == "rti":
        return coverage(directions, Cap(sphere.zenith_min, sphere.zenith_max))["covering_radius_deg"]
    scene = (setup if calibration is None else calibrated_setup(setup, calibration)).scene
    images = np.stack([c.image for c in captures])  # linearised by the calibrated response
    recovery = recover_from_scene(scene, directions, images, spec.dark_level, spec.saturation_level)
    error = recovery.angular_error(gbuffer_normal_map(setup.scene))[scene.gbuffer.mask]
    return float(np.mean(np.where(np.isnan(error), 90.0, error)))


def improves(cost: float, kept: float, tolerance: float) -> bool:
    """A measured ``cost`` is an improvement on the ``kept`` one when it is at least ``tolerance``
    (relative) below it: the loop's stop rule and its choice of plan. A smaller decrease is within
    what the camera's noise makes."""
    return cost < kept * (1.0 - tolerance)


@dataclass(frozen=True, eq=False)
class Iteration:
    """One round of the loop: the ``plan`` (made on the model of the previous round's calibration,
    the problem's model for round 0), its ``captures``, the ``measured`` and ``modelled`` cost of each
    capture, the ``calibration`` fitted after it (None when it failed: ``calibration_error`` says why),
    the round's ``wall_time_s`` (plan, capture and calibration) and its ``measure``
    (:func:`round_measure`; None: the measured cost)."""

    index: int
    plan: Plan
    captures: tuple[Capture, ...]
    measured: Array
    modelled: Array
    calibration: Calibration | None
    wall_time_s: float
    calibration_error: str | None = None
    measure: float | None = None

    @property
    def score(self) -> float:
        """What the loop judges the round by: its ``measure`` (the measured cost when None)."""
        return self.measured_cost if self.measure is None else self.measure

    @property
    def measured_cost(self) -> float:
        """Mean measured cost over the captures."""
        return float(np.mean(self.measured))

    @property
    def modelled_cost(self) -> float:
        """Mean modelled cost over the captures."""
        return float(np.mean(self.modelled))

    def to_dict(self) -> dict[str, Any]:
        """JSON-safe: costs, landmarks, wall time, calibration."""
        sphere = self.plan.setup.sphere
        zenith, azimuth = sphere.angles(np.array([c.light_position for c in self.captures]))
        return {
            "iteration": self.index,
            "measured_cost": self.measured_cost,
            "modelled_cost": self.modelled_cost,
            "measure": self.score,
            "measured_per_capture": self.measured,
            "modelled_per_capture": self.modelled,
            "landmarks": [
                {
                    "zenith_deg": float(np.rad2deg(z)),
                    "azimuth_deg": float(np.rad2deg(a)),
                    "light_position_m": c.light_position,
                }
                for z, a, c in zip(zenith, azimuth, self.captures, strict=True)
            ],
            "wall_time_s": self.wall_time_s,
            "plan_time_s": self.plan.timings.get("total"),
            "verification_passed": self.plan.verification.passed,
            "calibration": None if self.calibration is None else self.calibration.to_dict(),
            "calibration_error": self.calibration_error,
        }


@dataclass(frozen=True, eq=False)
class Acquisition:
    """The result of :func:`acquire`: the problem's ``setup``, the ``camera`` kind, every round in
    ``iterations``, why the loop stopped (``status``: "stopped improving", "iteration limit",
    "awaiting captures", "calibration failed", "re-plan failed (…)") and, with a folder camera, the ``next_plan`` to run."""

    setup: Setup
    camera: str
    iterations: tuple[Iteration, ...]
    status: str
    next_plan: Plan | None = None
    exposure: dict[str, Any] = field(default_factory=dict)

    @property
    def measure(self) -> str:
        """The name of what the loop judges rounds by (:data:`MEASURES`)."""
        return MEASURES[self.setup.problem.lightset.kind]

    @property
    def best(self) -> Iteration:
        """The round the loop keeps: the first, replaced by a later one only when its measure
        (:attr:`Iteration.score`) is at least ``[loop] tolerance`` (relative) below the kept round's —
        the rule that stops the loop.
        A smaller decrease is within what the camera's noise makes: keeping such a round was measured
        worse than the open loop when captured again (bench_loop's light_2cm_off, ratio 1.00006)."""
        tolerance = self.setup.problem.loop.tolerance
        kept = self.iterations[0]
        for it in self.iterations[1:]:
            if improves(it.score, kept.score, tolerance):
                kept = it
        return kept

    @property
    def open_loop(self) -> Iteration:
        """Round 0: the plan on the problem's own model."""
        return self.iterations[0]

    @property
    def calibration(self) -> Calibration | None:
        """The last calibration fitted (from every usable capture)."""
        return next((it.calibration for it in reversed(self.iterations) if it.calibration is not None), None)

    def summary(self) -> dict[str, Any]:
        """The key numbers, JSON-safe (no costs before the first round's captures)."""
        head = {
            "problem": self.setup.problem.name,
            "camera": self.camera,
            "status": self.status,
            "iterations": len(self.iterations),
        }
        if not self.iterations:
            return head
        best, first = self.best, self.open_loop
        return {
            **head,
            "measure": self.measure,
            "open_loop_measure": first.score,
            "best_measure": best.score,
            "ratio_best_over_open_loop_measure": best.score / first.score if first.score > 0 else None,
            "best_iteration": best.index,
            "open_loop_measured_cost": first.measured_cost,
            "best_measured_cost": best.measured_cost,
            "ratio_best_over_open_loop": best.measured_cost / first.measured_cost
            if first.measured_cost > 0
            else None,
            "wall_time_per_iteration_s": [it.wall_time_s for it in self.iterations],
        }

    def instructions(self, folder: str | Path, command: str) -> str:
        """What the user does next, in plain text: with a round awaiting captures, where the robot's
        files are, which images to save where, and ``command`` (the one that continues); else where
        the dataset is."""
        out = Path(folder)
        if self.next_plan is None:
            return f"{self.status}: the dataset is in {out}/ (README.md says what each file holds)"
        index, plan = len(self.iterations), self.next_plan
        sub = out / round_folder(index)
        names = image_names(round_pattern(index), len(plan.visited))
        camera = plan.scene.camera
        limit = self.setup.problem.loop.iterations
        what = "the open loop's plan, on the problem's model" if index == 0 else "re-planned on the calibrated model"
        return "\n".join(
            [
                f"round {index} ({what}; at most {limit} rounds, 0 to {limit - 1}): the files for the robot and "
                f"the camera are in {sub}/",
                f"  1. move the robot to the first point of {sub / 'joint_trajectory.yaml'} (a ROS 2 "
                "JointTrajectory; trajectory.csv holds the same motion sampled in time) and run it",
                f"  2. trigger the camera at each trigger_s of {sub / 'captures.csv'} (seconds from the start "
                f"of the motion; the light rests there from dwell_start_s to dwell_end_s): {len(names)} images",
                f"  3. save each image under the name in the image column of its row ({names[0]} … {names[-1]}) "
                f"in {sub}/: PNG or TIFF, {camera.width}×{camera.height} px, with the camera's settings "
                "(exposure, gain, response) those of every other round",
                "then run the same command again; it continues from there:",
                f"  {command}",
            ]
        )

    def readme(self) -> str:
        """The dataset folder's README.md: what each file holds and the frame of every direction."""
        rounds = self.camera == "folder"
        best = f"round {self.best.index}" if self.iterations else "none yet"
        per_round = (
            "- `round_NN/`: round NN's plan (what `optlight solve` writes: trajectory.csv, "
            "joint_trajectory.yaml, captures.csv with the trigger times, lights.lp, plan.json, report.md) "
            "and the images saved there for it, named `rNN_000.png` …"
            if rounds
            else "- `iterations/NN/`: round NN's images, captures.csv and lights.lp"
        )
        lines = [
            f"# {self.setup.problem.name}: camera in the loop ({self.camera} camera)",
            "",
            f"Status: {self.status}. The best round (lowest {self.measure}): {best}.",
            "",
            "## Files",
            "",
            "- `captures.csv`, `lights.lp` and the images they name: the best round's captures, 16-bit "
            "greyscale PNG of the recorded values (0 is black, 65535 the saturation value; the camera's "
            "response is calibration.json's `gamma`), the same names in both files",
            per_round,
            "- `calibration.json`, `albedo_factor.npy` (H, W), `normals.npy` (H, W, 3, world frame; zeros "
            "where not recovered): the calibrated model",
            "- `acquisition.json`: per round the measured and modelled cost, the lights, the calibration",
            "- `measured_cost.png`: the measured and modelled cost per round",
            "",
            "## Frames",
            "",
            f"- Light directions (captures.csv's `{'`, `'.join(LIGHT_DIRECTION_COLUMNS)}`, lights.lp, a "
            f"DiLiGenT folder's light_directions.txt): {LIGHT_FRAME}.",
            "- `zenith_deg`, `azimuth_deg` (captures.csv, acquisition.json): the light on the light sphere "
            "around the object, zenith from the direction towards the camera, azimuth 0 to the right of "
            "the image and 90 towards its top: the angles `optlight render --zenith --azimuth` takes.",
            "- Light positions (`light_position_*_m`) and normals.npy: the problem's world frame, metres.",
            "",
        ]
        return "\n".join(lines)

    def figure(self) -> Figure:
        """Measured and modelled cost per iteration."""
        from matplotlib.figure import Figure

        fig = Figure(figsize=(5.5, 3.6))
        ax = fig.add_subplot()
        k = [it.index for it in self.iterations]
        ax.plot(
            k, [it.measured_cost for it in self.iterations], "o-", label=f"measured ({self.camera} camera)"
        )
        ax.plot(k, [it.modelled_cost for it in self.iterations], "s--", label="modelled (the planning model)")
        ax.axvline(self.best.index, color="0.7", lw=0.8)
        ax.set_xlabel("iteration (0 = open loop)")
        ax.set_ylabel("mean cost per capture")
        ax.set_xticks(k)
        ax.set_title(f"{self.setup.problem.name}: camera in the loop ({self.status})")
        ax.legend()
        fig.tight_layout()
        return fig

    def save(self, folder: str | Path, *, overwrite: bool = False) -> list[Path]:
        """Write the dataset folder, whole or not at all, and return the files written. ``folder``
        must be new, empty or, with ``overwrite``, an earlier optlight output of which only the files
        its manifest lists are replaced; anything else is refused (:class:`UsageError`, nothing
        written): the output policy of :mod:`optlight.export`.

        - ``captures.csv``, ``lights.lp`` and the images they name: the best round's captures
          (16-bit PNG, full scale = the saturation value), readable back by :class:`FolderCamera`;
        - ``iterations/NN/``: every round's images and captures.csv;
        - ``calibration.json`` (the last calibration's parameters and fit statistics) with
          ``albedo_factor.npy`` (H, W; 1 where not calibrated) and, when recovered, ``normals.npy``
          (H, W, 3, world frame, zeros where not recovered);
        - ``acquisition.json``: per round the measured and modelled cost, the landmarks, the wall time
          and the calibration; the summary; library versions;
        - ``measured_cost.png``: :meth:`figure`;
        - ``README.md``: the files and the frame of their light directions;
        - with the folder camera, ``round_NN/`` instead of ``iterations/NN/``: each round's plan folder
          (:meth:`Plan.save <optlight.plan.Plan.save>` without the preview), the round awaiting
          captures last; the images the user saved there are never written (module docstring).

        With the folder camera an acquisition in rounds (:data:`ROUNDS`) in ``folder`` is continued
        without ``overwrite``; until the loop has ended, the folder's manifest says it may be.
        """
        rounds = self.camera == "folder"
        return write_folder(
            folder,
            lambda staging: [staging / f for f in self._write(staging)],
            overwrite=overwrite,
            resume=ROUNDS if rounds else None,
            resumable=ROUNDS if rounds and self.status == AWAITING else None,
        )

    def _write(self, root: Path) -> list[str]:
        files: list[str] = []
        if self.camera == "folder":
            plans = [it.plan for it in self.iterations] + ([self.next_plan] if self.next_plan else [])
            for index, plan in enumerate(plans):
                written = plan.save(root / round_folder(index), preview=False)
                # a round folder carries its own manifest (a results folder of its own); the dataset's lists it too
                files += [str(Path(p).relative_to(root)) for p in written] + [f"{round_folder(index)}/{MANIFEST}"]
        else:
            for it in self.iterations:
                sub = Path("iterations") / f"{it.index:02d}"
                files += [str(sub / f) for f in _write_captures_folder(root / sub, it)]
        if self.iterations:
            files += _write_captures_folder(root, self.best)
        calibration = self.calibration
        if calibration is not None:
            scene = self.setup.scene
            (root / "calibration.json").write_text(
                json.dumps(json_safe(calibration.to_dict()), indent=2) + "\n"
            )
            np.save(
                root / "albedo_factor.npy", scene.to_image(calibration.albedo_factor) + ~scene.gbuffer.mask
            )
            files += ["calibration.json", "albedo_factor.npy"]
            if calibration.normals is not None and calibration.normals_valid is not None:
                h, w = scene.gbuffer.mask.shape
                normals = np.zeros((h * w, 3))
                valid = calibration.normals_valid
                normals[scene.gbuffer.pixel_index[valid]] = calibration.normals[valid]
                np.save(root / "normals.npy", normals.reshape(h, w, 3))
                files.append("normals.npy")
        if self.iterations:
            self.figure().savefig(root / "measured_cost.png", dpi=120)
            files.append("measured_cost.png")
        (root / "README.md").write_text(self.readme())
        files.append("README.md")
        document = {
            **self.summary(),
            "problem_definition": self.setup.problem.to_dict(),
            "exposure": self.exposure,
            "loop": self.setup.problem.to_dict().get("loop", {}),
            "world": self.setup.problem.to_dict().get("world", {}),
            "iterations_detail": [it.to_dict() for it in self.iterations],
            "versions": library_versions(),
            "files": [*files, "acquisition.json"],
        }
        (root / "acquisition.json").write_text(
            json.dumps(json_safe(document), indent=2, allow_nan=False) + "\n"
        )
        files.append("acquisition.json")
        return files


def _write_captures_folder(folder: Path, iteration: Iteration) -> list[str]:
    """An iteration's images, captures.csv and lights.lp in ``folder``; returns the names written."""
    plan = iteration.plan
    spec = plan.problem.trajectory
    folder.mkdir(parents=True, exist_ok=True)
    positions = np.array([c.light_position for c in iteration.captures])
    directions = positions - plan.setup.sphere.center
    directions = plan.scene.camera.to_camera_frame(
        directions / np.linalg.norm(directions, axis=1, keepdims=True)
    )
    write_captures(
        folder / "captures.csv",
        plan.trajectory,
        settle_s=spec.settle_s,
        image_pattern=spec.image_pattern,
        light_directions_camera=directions,
        light_positions=positions,
        light_angles_deg=np.rad2deg(np.column_stack(plan.setup.sphere.angles(positions))),
        joint_names=plan.robot.joint_names,
    )
    names = [spec.image_pattern.format(index=i) for i in range(len(iteration.captures))]
    for name, capture in zip(names, iteration.captures, strict=True):
        write_capture_png(folder / name, capture.image, plan.problem.light.saturation)
    (folder / "lights.lp").write_text(lp_text(names, lp_direction(directions)))
    return ["captures.csv", "lights.lp", *names]


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
        try:
            plan = solve(round_setup(model, i) if device.kind == "folder" else model, progress=_stage_progress(notify, i))
        except OptlightError as e:
            if i == 0:
                raise
            status = f"re-plan failed ({e})"
            break
        if not plan.verification.passed:
            if i == 0:
                raise VerificationError(
                    f"iteration {i}: the plan failed verification; the robot does not run it\n"
                    f"{plan.verification.summary()}",
                    plan.verification,
                )
            failed = ", ".join(name for name, check in plan.verification.checks.items() if not check.passed)
            status = f"re-plan failed verification ({failed}); the robot does not run it"
            break
        notify(i, "capture", 0, len(plan.visited))
        current = device.camera(i) if isinstance(device, RoundFolders) else device
        if current is None:
            status, next_plan = AWAITING, plan
            break
        try:
            captures = execute(plan, current)
        except MissingCaptureError as e:
            if isinstance(device, RoundFolders):
                raise OptlightError(
                    f"{e}: round {i}'s images were taken for another plan than the one planned again for it "
                    "(the problem file, or an earlier round's images, changed since)"
                ) from None
            if i == 0:
                raise
            status, next_plan = AWAITING, plan
            break
        notify(i, "capture", len(captures), len(captures))
        measured = measured_costs(setup, captures)
        modelled = modelled_costs(model, [c.light_position for c in captures])
        pool += captures
        notify(i, "calibrate", 0, 1)
        calibration, error = None, None
        try:
            calibration = calibrate(setup.scene, pool, spec)
        except OptlightError as e:
            error = str(e)
        notify(i, "calibrate", 1, 1)
        measure = None if setup.problem.lightset.kind == "none" else round_measure(setup, plan, captures, calibration)
        rounds.append(
            Iteration(
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
        )
        cost = rounds[-1].score
        if i > 0 and not improves(cost, best, spec.tolerance):
            status = "stopped improving"
            break
        best = min(best, cost)
        if calibration is None:
            status = "calibration failed"
            break
        model = calibrated_setup(setup, calibration, spec.normals)
    exposure = dict(rounds[0].captures[0].exposure) if rounds and rounds[0].captures else {}
    return Acquisition(setup, device.kind, tuple(rounds), status, next_plan, exposure)


def _stage_progress(notify: LoopProgress, iteration: int) -> Callable[[str, int, int], None]:
    """:func:`optlight.solve`'s progress as the loop's, for one iteration."""
    return lambda stage, done, total: notify(iteration, f"plan: {stage}", done, total)


# --------------------------------------------------------------------------------------------
# The photometric servo
# --------------------------------------------------------------------------------------------


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
