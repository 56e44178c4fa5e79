"""The results folder of a plan: files, figures, the offline preview and a readable report.

Built from a solved plan as :class:`PlanRecord` sees it (the setup, the landmark search, the landmarks
visited and their joint angles, the path, the trajectory NLP, the timed trajectory, the verification):
:class:`~optlight.plan.Plan` is one, and sits above this module. ``save_results(folder, plan, ...)``
writes, all at once or not at all (:func:`optlight.export.write_results`):

- ``trajectory.csv`` (at ``[trajectory] rate_hz``), ``plan.json``, ``lights.lp`` (relight / PTM light
  directions), ``joint_trajectory.yaml`` (ROS 2 JointTrajectory: the controller waypoints),
  ``follow_joint_trajectory_goal.yaml`` (the same as a FollowJointTrajectory goal), ``captures.csv``
  (trigger times);
- ``trajectory.png`` (q, q̇, q̈ against the limits), ``path.png`` (the light's path on the sphere),
  ``landmarks_*.png`` (polar plot, histograms, camera images, cost map);
- ``preview.html`` (Meshcat, opens with no server) and ``report.md`` (the figures and key numbers);
- for a light set, what :class:`~optlight.plan.Plan` adds: ``photometric_stereo/`` (the DiLiGenT
  layout, :func:`optlight.datasets.model_capture`), ``normal_map.png`` and ``normal_error.png``, and
  with a reachability map (``[lightset] design_over = "reachable"``) ``lightset_reach.png``.

The figures can be drawn while the plan is still being solved: :class:`FigureDrafts` listens to the
solve's stages (:mod:`optlight.stages`) and hands a worker process each figure as soon as its numbers
exist.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from concurrent.futures import Future
from functools import partial
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np
from numpy.typing import NDArray

from optlight.export import (
    LIGHT_DIRECTION_COLUMNS,
    LIGHT_FRAME,
    write_captures,
    write_joint_trajectory,
    write_results,
)
from optlight.motion import Trajectory
from optlight.planning.landmarks import Landmark, LandmarkSet
from optlight.planning.path import LightPath
from optlight.planning.policy import LandmarkPlacement
from optlight.planning.trajectory import TrajectoryNLPResult
from optlight.planning.waypoints import Waypoints
from optlight.scene import Scene
from optlight.setup import Setup
from optlight.stages import OptimizedPath
from optlight.verify import VerificationReport, capture_exposures
from optlight.viz.drawing import FigureJob
from optlight.viz.figures import LANDMARK_FIGURES, landmark_figures
from optlight.viz.trajectory_figures import path_figure, trajectory_figure

if TYPE_CHECKING:
    from optlight.viz.drawing import FigureWorker

Array = NDArray[np.float64]

#: Resolution (dots per inch) of the trajectory and path figures and of a light set's figures.
RESULTS_DPI = 120


class PlanRecord(Protocol):
    """What the results folder reads of a solved plan (:class:`~optlight.plan.Plan` is one: see its
    fields)."""

    @property
    def setup(self) -> Setup: ...
    @property
    def landmarks(self) -> LandmarkSet: ...
    @property
    def visited(self) -> Sequence[Landmark]: ...
    @property
    def landmark_thetas(self) -> Array: ...
    @property
    def path(self) -> LightPath: ...
    @property
    def nlp(self) -> TrajectoryNLPResult: ...
    @property
    def trajectory(self) -> Trajectory: ...
    @property
    def waypoints(self) -> Waypoints: ...
    @property
    def verification(self) -> VerificationReport: ...
    @property
    def timings(self) -> Mapping[str, float]: ...
    @property
    def warnings(self) -> Sequence[str]: ...
    @property
    def light_directions_camera(self) -> Array: ...


def plan_dict(plan: PlanRecord, summary: Mapping[str, Any]) -> dict[str, Any]:
    """What plan.json records of ``plan`` besides the trajectory and the verification (which export
    adds); ``summary`` its key numbers."""
    setup, landmarks, visited, warnings = plan.setup, plan.landmarks, plan.visited, plan.warnings
    landmark_thetas, path, nlp = plan.landmark_thetas, plan.path, plan.nlp
    problem, robot, spec = setup.problem, setup.robot, setup.problem.robot
    return {
        "problem": problem.to_dict(),
        "problem_file": str(problem.source) if problem.source else None,
        "robot": {
            "name": robot.name,
            "joint_names": robot.joint_names,
            "light_offset_m": spec.light_offset_m,
            "light_rpy_deg": spec.light_rpy_deg,
            "base_position_m": spec.base_position_m,
            "base_rpy_deg": spec.base_rpy_deg,
            "lower": robot.lower,
            "upper": robot.upper,
            "velocity_limit": setup.limits.velocity,
            "acceleration_limit": setup.limits.acceleration,
            "jerk_limit": setup.limits.jerk,
        },
        "landmarks": [
            {
                "capture": i,
                "index": lm.index,
                "zenith_deg": float(np.rad2deg(lm.zenith)),
                "azimuth_deg": float(np.rad2deg(lm.azimuth)),
                "position_m": lm.position,
                "cost": lm.cost,
                "status": lm.status,
                "solver_status": lm.solver_status,
                "iterations": lm.iterations,
                "time_s": lm.time_s,
                "theta": theta,
            }
            for i, (lm, theta) in enumerate(zip(visited, landmark_thetas, strict=True))
        ],
        "landmark_search": {
            "mode": landmarks.mode,
            "reference": landmarks.reference_label,
            "resolution": landmarks.resolution,
            "iterations": landmarks.iterations,
            "time_s": landmarks.time_s,
        },
        "trajectory_nlp": {
            "status": nlp.status,
            "success": nlp.success,
            "cost": nlp.cost,
            "iterations": nlp.iterations,
            "max_h_residual_m": nlp.max_h_residual,
            "time_s": nlp.time_s,
            "knots": path.n_knots,
            "landmark_knots": path.landmark_knots,
            "transfers": np.flatnonzero(path.transfers),  # segments off the sphere, in visiting order
        },
        "summary": dict(summary),
        "warnings": list(warnings),
    }


def report_markdown(plan: PlanRecord, summary: Mapping[str, Any], figures: Sequence[str]) -> str:
    """report.md of ``plan``: what was solved, the key numbers (``summary``), the verification and the
    ``figures`` (PNG file names)."""
    setup, timings, verification, warnings = plan.setup, plan.timings, plan.verification, plan.warnings
    s, t = summary, timings
    view = setup.problem.view
    protected = (
        "> **The camera's view is not protected** (`[view] mode = \"off\"`): robot links or the lamp may "
        "stand between the camera and the object in these images."
        if view.mode == "off"
        else f"The camera's view of the object is kept clear of the robot and the lamp "
        f"{'at every capture' if view.mode == 'capture' else 'along the whole motion'}; lights nearer "
        f"the camera's axis than zenith {math.degrees(setup.view_zenith):.1f}° are left out (the lamp "
        "would be in front of the lens)."
    )
    lines = [
        f"# optlight plan: {setup.problem.name}",
        "",
        protected,
        "",
        setup.problem.description,
        "",
        "Open `preview.html` in a browser for the 3-D preview (robot, object, light sphere, landmarks,",
        "path, camera, the obstacles of `[environment]`; the trajectory plays as an animation).",
        "",
        "## Key numbers",
        "",
        "| quantity | value |",
        "|---|---|",
        f"| robot | {s['robot']} |",
        f"| landmarks (captures) | {s['landmarks']} |",
        f"| mean landmark cost | {s['mean_landmark_cost']:.3g} |",
        f"| path knots | {s['knots']} |",
        f"| trajectory NLP | {s['nlp_status']}, {s['nlp_iterations']} iterations |",
        f"| max light-constraint residual h | {s['max_h_residual_m']:.2e} m |",
        f"| joint path length (NLP / per-knot IK) | {s['joint_path_length_rad']:.3f} rad / "
        f"{s['knot_ik_path_length_rad']:.3f} rad |",
        f"| duration (motion + dwells) | {s['duration_s']:.2f} s ({s['motion_time_s']:.2f} s moving) |",
        f"| moving time / rest-to-rest bound (time-optimal stops at the same postures) | "
        f"{s['motion_bound']['motion_time_s']:.2f} s / {s['motion_bound']['rest_to_rest_s']:.2f} s "
        f"({s['motion_bound']['ratio']:.2f}×) |",
        *(
            [
                f"| moving time / flying bound (any motion through the same postures, stopping only where a joint turns) | "
                f"{s['motion_bound']['motion_time_s']:.2f} s / {s['motion_bound']['flying_s']:.2f} s "
                f"({s['motion_bound']['flying_ratio']:.2f}×) |"
            ]
            if "flying_s" in s["motion_bound"]
            else []
        ),
        f"| timing | {setup.trajectory_spec.timing.replace('_', '-')}, exported at "
        f"{setup.trajectory_spec.rate_hz:g} Hz |",
        f"| controller waypoints (joint_trajectory.yaml) | {s['controller_waypoints']} |",
        f"| peak joint torque / limit (the lamp {setup.problem.light.mass_kg:g} kg) | {_torque_text(verification)} |",
        f"| verification | {'passed' if s['verification_passed'] else 'FAILED'} |",
        "",
        "## Time per stage",
        "",
        "| stage | seconds |",
        "|---|---|",
        *(f"| {name} | {t[name]:.3f} |" for name in t),
        "",
        "## Verification",
        "",
        "```",
        verification.summary(),
        "```",
        "",
    ]
    if "lightset" in s:
        lines += _lightset_lines(s["lightset"])
    if warnings:
        lines += ["## Warnings", "", *(f"- {w}" for w in warnings), ""]
    holders = f"captures.csv's `{'`, `'.join(LIGHT_DIRECTION_COLUMNS)}`, `lights.lp`"
    if "lightset" in s:
        holders += ", the DiLiGenT folder's `light_directions.txt`"
    lines += [
        "## Files and frames",
        "",
        "- `joint_trajectory.yaml` (ROS 2 JointTrajectory) and `trajectory.csv`: the motion; "
        "`captures.csv`: per capture the camera trigger (`trigger_s`), the image name, the light's "
        "`zenith_deg` and `azimuth_deg` (the angles `optlight render --zenith --azimuth` takes), its "
        "direction, its position (`light_position_*_m`, world frame, m), the joint angles, the exposure "
        "(`exposure_start_s`, `exposure_end_s`: start the camera's exposure at the first) and the blur the "
        "motion gives it (`blur_deg` about the object's centre, `blur_mm`).",
        f"- Light directions ({holders}): {LIGHT_FRAME}.",
        "- Image names: the same in every file that names the images.",
        "",
    ]
    lines += ["## Figures", ""]
    lines += [f"![{Path(f).stem}]({f})\n" for f in figures]
    return "\n".join(lines)


def _torque_text(verification: VerificationReport) -> str:
    """The largest fraction of a torque limit a joint reaches, and which; or why none is checked."""
    torques = verification.torques
    if torques is None:
        return "not computed"
    if torques.fraction is None:
        return f"not checked: {torques.source}"
    j = max(range(len(torques.joints)), key=lambda i: torques.fraction[i] if torques.fraction else 0.0)
    return f"{torques.fraction[j]:.0%} ({torques.joints[j]}; every joint under Verification)"


def _lightset_lines(lightset: Mapping[str, Any]) -> list[str]:
    """report.md's section on a light set: requested vs achieved lights, set cost, capture order."""
    travel = lightset["order_joint_travel_rad"]
    lines = [
        "## Light set",
        "",
        "| quantity | value |",
        "|---|---|",
        f"| kind | {lightset['kind']} |",
        f"| lights requested / achieved | {lightset['requested']} / {lightset['achieved']} |",
        f"| moved by the placement | {len(lightset['moved_by_placement'])} |",
        f"| dropped | {len(lightset['dropped'])} |",
    ]
    if "reach_map" in lightset:
        reach = lightset["reach_map"]
        lines.append(
            f"| reachability map (`lightset_reach.png`) | {reach['clear_pct']:.0f} % of the cap's "
            f"{reach['map_cells']} cells reached clear, in {reach['map_time_s']:.1f} s |"
        )
    if "grid" in lightset:
        grid = lightset["grid"]
        lines.append(
            f"| grid lights replaced on the allowed cap | {len(grid['replaced'])} (up to {grid['max_moved_deg']:.1f}°) |"
        )
    if "set_cost_requested" in lightset:
        lines.append(
            f"| set cost requested → achieved | {lightset['set_cost_requested']:.4g} → "
            f"{lightset['set_cost_achieved']:.4g} |"
        )
    if "recovery" in lightset:
        r = lightset["recovery"]
        lines.append(
            f"| normals recovered from the model's images (`photometric_stereo/`) | {r['recovered_pct']:.1f} % "
            f"of the object, angular error mean {r['mean_deg']:.2f}°, p95 {r['p95_deg']:.2f}° |"
        )
    lines += [
        f"| joint travel, tour / azimuth order | {travel['tour']:.2f} rad / {travel['azimuth']:.2f} rad |",
        f"| design time | {lightset['design_time_s']:.2f} s |",
        "",
    ]
    return lines


def landmark_jobs(landmarks: LandmarkSet, scene: Scene, captures: Sequence[Landmark]) -> dict[str, FigureJob]:
    """The landmark figures of a results folder (:func:`~optlight.viz.figures.landmark_figures`),
    with the plan's ``captures`` that the placement moved drawn where they are captured; none for a
    light set, which has no sweep or reference."""
    return landmark_figures(landmarks, scene, captures) if _landmark_figure_names(landmarks) else {}


def _landmark_figure_names(landmarks: LandmarkSet) -> tuple[str, ...]:
    """The file stems of :func:`landmark_jobs`, without making the jobs."""
    return LANDMARK_FIGURES if landmarks.mode != "set" else ()


def motion_jobs(
    setup: Setup, visited: Sequence[Landmark], knot_thetas: Array, trajectory: Trajectory
) -> dict[str, FigureJob]:
    """The figures of the robot's motion: ``trajectory`` (q, q̇, q̈ of the timed ``trajectory``
    against the setup's limits) and ``path`` (the light on the sphere: at the knots' joint angles
    ``knot_thetas`` (K, n, rad), off the sphere on the transfers; along the trajectory at 20 Hz; at
    the ``visited`` landmarks)."""
    robot, limits = setup.robot, setup.limits
    timed = trajectory.sample(trajectory.sample_times(20.0))[0]
    bounds = partial(
        trajectory_figure,
        lower=limits.lower,
        upper=limits.upper,
        velocity_limit=limits.velocity,
        acceleration_limit=limits.acceleration,
    )
    positions = (
        robot.light_positions(knot_thetas),
        robot.light_positions(timed),
        np.array([lm.position for lm in visited]),
    )
    return {
        "trajectory": FigureJob(bounds, (trajectory,), RESULTS_DPI),
        "path": FigureJob(path_figure, (setup.sphere, *positions), RESULTS_DPI),
    }


def _png_source(job: FigureJob, worker: FigureWorker | None) -> Callable[[], bytes]:
    """Where the PNG of a figure no worker drew yet comes from: the worker now, else this process
    when asked."""
    return worker.draw(job).result if worker is not None else job.png


def save_results(
    folder: str | Path,
    plan: PlanRecord,
    *,
    summary: Mapping[str, Any],
    preview: Callable[[Path], Path] | None = None,
    overwrite: bool = False,
    extra_figures: Mapping[str, FigureJob] | None = None,
    extra_writers: Sequence[Callable[[Path], list[Path]]] = (),
    worker: FigureWorker | None = None,
    drawn: Mapping[str, Future[bytes]] | None = None,
) -> list[Path]:
    """Write the results folder of a verified ``plan`` (see the module docstring), with its key
    numbers ``summary``; returns the paths. ``preview(path)`` writes ``preview.html`` (left out when
    None); ``extra_figures`` and ``extra_writers`` add figures and files (a light set's
    photometric-stereo folder); ``worker`` draws the figures while the rest is written
    (:mod:`optlight.viz.drawing`), else they are drawn here; ``drawn`` are figures a worker drew (or
    is drawing) already, by file stem (:attr:`FigureDrafts.figures`).

    ``folder`` must be new, empty, or (with ``overwrite``) an earlier optlight output, of which only
    the files optlight wrote are replaced (the output policy of :mod:`optlight.export`)."""
    setup, landmarks, visited, nlp = plan.setup, plan.landmarks, plan.visited, plan.nlp
    trajectory, waypoints, verification = plan.trajectory, plan.waypoints, plan.verification
    light_directions_camera = plan.light_directions_camera
    robot = setup.robot
    drawn = {name: png for name, png in (drawn or {}).items() if not png.cancelled()}
    # the landmark jobs only when one is not drawn: making the contact sheet's renders its images
    missing = not drawn.keys() >= set(_landmark_figure_names(landmarks))
    figures = {
        **motion_jobs(setup, visited, nlp.theta, trajectory),
        **(landmark_jobs(landmarks, setup.scene, visited) if missing else {}),
        **(extra_figures or {}),
    }
    sources: dict[str, Callable[[], bytes]] = {name: png.result for name, png in drawn.items()}
    sources |= {name: _png_source(job, worker) for name, job in figures.items() if name not in drawn}

    def preview_html(folder: Path) -> list[Path]:
        assert preview is not None
        return [preview(folder / "preview.html")]

    def report(folder: Path) -> list[Path]:
        names = sorted(f"{name}.png" for name in sources)
        out = folder / "report.md"
        out.write_text(report_markdown(plan, summary, names))
        return [out]

    traj_spec = setup.trajectory_spec

    def joint_trajectory(folder: Path) -> list[Path]:
        return write_joint_trajectory(folder, waypoints, robot.joint_names)

    def captures(folder: Path) -> list[Path]:
        return [
            write_captures(
                folder / "captures.csv",
                trajectory,
                settle_s=traj_spec.settle_s,
                image_pattern=traj_spec.image_pattern,
                light_directions_camera=light_directions_camera,
                light_positions=np.array([lm.position for lm in visited]),
                light_angles_deg=np.rad2deg([(lm.zenith, lm.azimuth) for lm in visited]).reshape(-1, 2),
                joint_names=robot.joint_names,
                exposures=capture_exposures(
                    trajectory, traj_spec.settle_s, traj_spec.exposure_s, robot.light_pose, setup.sphere.center
                ),
            )
        ]

    writers = [
        joint_trajectory,
        captures,
        *([preview_html] if preview is not None else []),
        *extra_writers,
        report,
    ]
    return write_results(
        folder,
        trajectory=trajectory,
        report=verification,
        plan_dict=plan_dict(plan, summary),
        joint_names=robot.joint_names,
        light_directions_camera=light_directions_camera,
        image_pattern=setup.trajectory_spec.image_pattern,
        figures=sources,
        writers=writers,
        overwrite=overwrite,
        csv_rate_hz=traj_spec.rate_hz,
    )


class FigureDrafts:
    """A stage listener (:data:`optlight.stages.StageListener`: ``solve(..., on_stage=drafts)``)
    that hands ``worker`` the results folder's figures as soon as their numbers exist: the landmark
    figures once the captures are placed (drawn while the motion is planned), the trajectory and path
    figures once the motion is timed (drawn while it is verified and the rest is written).
    :attr:`figures`, by file stem, go to :meth:`~optlight.plan.Plan.save` (``drawn=``), which takes
    them as they are: the same figures :func:`save_results` would draw."""

    def __init__(self, worker: FigureWorker) -> None:
        self.worker = worker
        self.figures: dict[str, Future[bytes]] = {}
        self._setup: Setup | None = None
        self._landmarks: LandmarkSet | None = None
        self._knots: OptimizedPath | None = None

    def __call__(self, stage: str, result: object) -> None:
        """Hear that ``stage`` finished with ``result`` (the table of :mod:`optlight.stages`)."""
        match result:
            case Setup():
                self._setup = result
            case LandmarkSet():
                self._landmarks = result
            case LandmarkPlacement():
                assert self._setup is not None and self._landmarks is not None, "scene and landmarks first"
                self._draw(landmark_jobs(self._landmarks, self._setup.scene, result.landmarks))
            case OptimizedPath():
                self._knots = result
            case Trajectory():
                assert self._setup is not None and self._knots is not None, "scene and nlp first"
                self._draw(motion_jobs(self._setup, self._knots.visited, self._knots.nlp.theta, result))

    def _draw(self, jobs: Mapping[str, FigureJob]) -> None:
        self.figures |= {name: self.worker.draw(job) for name, job in jobs.items()}
