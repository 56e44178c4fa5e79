"""A solved problem: where the light goes, how the robot gets there, and the proof it is safe.

:class:`Plan` holds the result of every stage of :func:`optlight.solve` (each a typed value of its
own module) and composes them for the user: the key numbers (:meth:`Plan.summary`), the 3-D preview
(:meth:`Plan.preview`) and the results folder (:meth:`Plan.save`, through :mod:`optlight.report`).
"""

from __future__ import annotations

from collections.abc import Mapping
from concurrent.futures import Future
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from optlight.datasets import ModelCapture, files_writer, model_capture
from optlight.environment import OBJECT
from optlight.motion import Trajectory
from optlight.planning.jerk import nonstop_bound, rest_to_rest_moves
from optlight.planning.landmarks import Landmark, LandmarkSet
from optlight.planning.path import LightPath
from optlight.planning.reach import ReachabilityMap
from optlight.planning.trajectory import TrajectoryNLPResult
from optlight.planning.waypoints import Waypoints
from optlight.report import RESULTS_DPI, save_results
from optlight.robot import Robot
from optlight.scene import Scene
from optlight.setup import Setup
from optlight.spec import Problem
from optlight.spec.sizing import image_names
from optlight.verify import VerificationReport
from optlight.viz.drawing import FigureJob, FigureWorker
from optlight.viz.preview import Preview

Array = NDArray[np.float64]

#: Subfolder of the results folder with a light set's model images in the DiLiGenT layout.
PHOTOMETRIC_STEREO_FOLDER = "photometric_stereo"


@dataclass(frozen=True)
class Plan:
    """A solved problem.

    ``setup`` the built problem; ``landmarks`` the landmark search; ``visited`` the landmarks kept,
    in visiting order; ``landmark_thetas`` (M, n) joint angles at them; ``path`` the light's knots;
    ``knot_ik`` the per-knot IK configurations (K, n) (the paper's pipeline); ``nlp`` the optimised
    knots; ``trajectory`` the timed motion; ``waypoints`` its points for a controller that interpolates
    quintically (joint_trajectory.yaml); ``verification`` the independent check; ``timings``
    seconds per stage and ``total``; ``warnings`` what was dropped or degraded; ``lightset`` a light
    set's requested vs achieved lights and set cost (:func:`~optlight.planning.set_landmarks.set_summary`),
    None without ``[lightset]``; ``reach`` the reachability map a light set was designed over (None
    for other plans).
    """

    setup: Setup
    landmarks: LandmarkSet
    visited: tuple[Landmark, ...]
    landmark_thetas: Array
    path: LightPath
    knot_ik: Array
    nlp: TrajectoryNLPResult
    trajectory: Trajectory
    waypoints: Waypoints
    verification: VerificationReport
    timings: dict[str, float]
    warnings: tuple[str, ...] = field(default=())
    lightset: dict[str, Any] | None = None
    reach: ReachabilityMap | None = None

    @property
    def problem(self) -> Problem:
        """The problem solved."""
        return self.setup.problem

    @property
    def scene(self) -> Scene:
        """The scene at the camera's resolution."""
        return self.setup.scene

    @property
    def robot(self) -> Robot:
        """The robot that carries the light."""
        return self.setup.robot

    @property
    def joint_path_length(self) -> float:
        """Σ_k |θ_{k+1} − θ_k| over the optimised knots (rad)."""
        return joint_path_length(self.nlp.theta)

    @property
    def motion_time(self) -> float:
        """Time spent moving (s): the trajectory's duration without the dwells."""
        intervals = self.trajectory.landmark_intervals
        return float(self.trajectory.duration - np.sum(intervals[:, 1] - intervals[:, 0]))

    def motion_bound(self) -> dict[str, float]:
        """The moving time against its rest-to-rest lower bound (s): the time-optimal moves between
        the trajectory's postures at its captures, in its order, from the start configuration to the
        first capture and back when the plan makes those moves, under the plan's velocity, acceleration and jerk limits
        (:func:`~optlight.planning.jerk.rest_to_rest_moves`, ruckig), independent of the plan's
        paths. ``ratio`` = moving time / bound (≥ 1); the ``between_captures`` pair leaves out the
        moves from and to the start.

        With flying captures also ``flying_s``, a bound for any motion through the same postures in
        the same order that need not stop at them (:func:`~optlight.planning.jerk.nonstop_bound`:
        the joints' velocity limits on every move, and each joint's stops where its own positions
        turn; the jerk limit and the blur speeds are left out, so it is loose), and ``flying_ratio``
        = moving time / flying_s."""
        trajectory, limits = self.trajectory, self.setup.limits
        intervals = trajectory.landmark_intervals
        approach = bool(intervals[0, 0] > 0)
        retreat = bool(trajectory.duration > intervals[-1, 1])
        # the trajectory's own postures: at each dwell (the trajectory NLP may move a capture's joints
        # in the arm's null space away from its placement), at the start and at the end
        q = trajectory.sample(np.r_[0.0, intervals[:, 0], trajectory.duration])[0]
        postures = q[(0 if approach else 1) : q.shape[0] - (0 if retreat else 1)]
        moves = rest_to_rest_moves(postures, limits.velocity, limits.acceleration, limits.jerk)
        inner = moves[int(approach) : moves.size - int(retreat)]
        segments = trajectory.segment_times
        bound = float(moves.sum())
        out = {
            "motion_time_s": self.motion_time,
            "rest_to_rest_s": bound,
            "ratio": self.motion_time / bound if bound > 0 else 1.0,
            "between_captures_s": float(np.sum(segments[:, 1] - segments[:, 0])),
            "between_captures_rest_to_rest_s": float(inner.sum()),
        }
        if self.problem.trajectory.capture == "flying":
            flying = nonstop_bound(postures, limits.velocity, limits.acceleration)
            out |= {"flying_s": flying, "flying_ratio": self.motion_time / flying if flying > 0 else 1.0}
        return out

    @property
    def light_directions_camera(self) -> Array:
        """(M, 3) unit vectors from the object to the light at each capture, OpenCV camera frame."""
        sphere = self.setup.sphere
        d = (np.array([lm.position for lm in self.visited]) - sphere.center) / sphere.radius
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
            "controller_waypoints": len(self.waypoints),
            "torque_peak_fraction": _torque_fractions(self.verification),
            "motion_bound": self.motion_bound(),
            "verification_passed": self.verification.passed,
            "min_clearance_m": {
                name: -check.max_value
                for name, check in self.verification.checks.items()
                if name in ("clearance", "self_collision", "view_cone")
            },
            "timings_s": dict(self.timings),
            **({"lightset": self.lightset} if self.lightset is not None else {}),
        }

    def preview(self) -> Preview:
        """The Meshcat preview: landmarks coloured by cost, the planned path, the trajectory as an
        animation, the object shaded for the first capture, the obstacles the plan keeps clear of
        (the object's bounding ball left out: its mesh is drawn). ``.save_html(path)`` or ``.show()``."""
        environment = self.setup.environment
        obstacles = environment.obstacles if environment is not None and environment.collisions else ()
        return Preview(
            self.scene,
            self.robot,
            np.array([lm.position for lm in self.visited]),
            np.array([lm.cost for lm in self.visited]),
            self.robot.light_positions(self.nlp.theta),  # the knots, off the sphere on the transfers
            self.trajectory,
            light_position=self.visited[0].position,
            obstacles=[o for o in obstacles if o.name != OBJECT],
        )

    def save(
        self,
        folder: str | Path,
        *,
        overwrite: bool = False,
        preview: bool = True,
        worker: FigureWorker | None = None,
        drawn: Mapping[str, Future[bytes]] | None = None,
    ) -> list[Path]:
        """Write the results folder (see :mod:`optlight.report`); refused (VerificationError) when the
        plan failed verification. ``folder`` must be new, empty or, with ``overwrite``, an earlier
        optlight output (the output policy of :mod:`optlight.export`). ``worker`` draws the figures
        in its process while this one writes the rest (:class:`~optlight.viz.drawing.FigureWorker`;
        the same files); ``drawn`` are the figures it drew while the plan was solved, by file stem
        (:attr:`optlight.report.FigureDrafts.figures`), taken as they are. Returns the paths written."""
        summary, writers = self.summary(), []
        figures: dict[str, FigureJob] = {}
        if self.lightset is not None:
            capture = self.model_capture()
            summary["lightset"] = {**self.lightset, "recovery": capture.stats}
            figures = {name: FigureJob.of(figure, RESULTS_DPI) for name, figure in capture.figures.items()}
            if self.reach is not None:
                reach = self.reach.figure(lights=self.light_directions_sphere)
                figures["lightset_reach"] = FigureJob.of(reach, RESULTS_DPI)
            writers = [files_writer(capture.files, PHOTOMETRIC_STEREO_FOLDER)]
        return save_results(
            folder,
            self,
            summary=summary,
            preview=(lambda path: self.preview().save_html(path)) if preview else None,
            overwrite=overwrite,
            extra_figures=figures,
            extra_writers=writers,
            worker=worker,
            drawn=drawn,
        )

    def model_capture(self) -> ModelCapture:
        """The visited lights captured by the model camera, normals recovered, in the DiLiGenT
        layout (:func:`optlight.datasets.model_capture`; ``[lightset]`` dark and saturation levels)."""
        spec, names = self.problem.lightset, image_names(self.problem.trajectory.image_pattern, len(self.visited))
        # the images keep the names of captures.csv and lights.lp
        return model_capture(self.scene, self.light_directions_sphere, spec.dark_level, spec.saturation_level, names)

    @property
    def light_directions_sphere(self) -> Array:
        """Unit directions (M, 3) from O to the visited lights, sphere frame."""
        sphere = self.setup.sphere
        d = (np.array([lm.position for lm in self.visited]) - sphere.center) @ sphere.rotation
        return d / np.linalg.norm(d, axis=1, keepdims=True)


def joint_path_length(theta: Array) -> float:
    """Σ_k |θ_{k+1} − θ_k| (rad) of a (K, n) knot sequence."""
    return float(np.sum(np.linalg.norm(np.diff(theta, axis=0), axis=1)))


def _torque_fractions(report: VerificationReport) -> dict[str, float] | None:
    """Per joint, its peak |τ| along the plan as a fraction of its torque limit; None for a robot
    without published limits or a report without torques."""
    torques = report.torques
    if torques is None or torques.fraction is None:
        return None
    return dict(zip(torques.joints, torques.fraction, strict=True))
