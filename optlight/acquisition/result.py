"""The loop's result: each round (:class:`Iteration`) and the whole (:class:`Acquisition`): which round
is kept, the key numbers, what the user does next, the README and figure of the dataset folder."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from optlight.acquisition.dataset import (
    write_calibration,
    write_captures_folder,
    write_document,
    write_round_plans,
)
from optlight.acquisition.measures import MEASURES, improves
from optlight.acquisition.rounds import AWAITING, ROUNDS, round_folder, round_pattern
from optlight.capture import Capture
from optlight.capture.calibration import Calibration
from optlight.export import LIGHT_DIRECTION_COLUMNS, LIGHT_FRAME, library_versions, write_folder
from optlight.plan import Plan
from optlight.setup import Setup
from optlight.spec.sizing import image_names

if TYPE_CHECKING:
    from matplotlib.figure import Figure

Array = NDArray[np.float64]

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
                f"  2. start the camera's exposure at each exposure_start_s of {sub / 'captures.csv'} (seconds "
                f"from the start of the motion; the light is at its landmark at trigger_s): {len(names)} images",
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
        """The dataset folder's files (:meth:`save`) written into ``root``; their names relative to it."""
        files: list[str] = []
        if self.camera == "folder":
            plans = [it.plan for it in self.iterations] + ([self.next_plan] if self.next_plan else [])
            files += write_round_plans(root, plans)
        else:
            for it in self.iterations:
                sub = Path("iterations") / f"{it.index:02d}"
                files += [str(sub / f) for f in write_captures_folder(root / sub, it.plan, it.captures)]
        if self.iterations:
            lamp = None if self.calibration is None else self.calibration.lamp
            files += write_captures_folder(root, self.best.plan, self.best.captures, lamp)
        if self.calibration is not None:
            files += write_calibration(root, self.setup.scene, self.calibration)
        if self.iterations:
            self.figure().savefig(root / "measured_cost.png", dpi=120)
            files.append("measured_cost.png")
        (root / "README.md").write_text(self.readme())
        files.append("README.md")
        problem = self.setup.problem.to_dict()
        document = {
            **self.summary(),
            "problem_definition": problem,
            "exposure": self.exposure,
            "loop": problem.get("loop", {}),
            "world": problem.get("world", {}),
            "iterations_detail": [it.to_dict() for it in self.iterations],
            "versions": library_versions(),
            "files": [*files, "acquisition.json"],
        }
        files.append(write_document(root, document))
        return files
