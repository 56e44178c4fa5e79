"""The results folder of a plan: files, figures, the offline preview and a readable report.

``save_plan(plan, folder)`` writes, all at once or not at all (:func:`optlight.export.write_results`):

- ``trajectory.csv``, ``plan.json``, ``lights.lp`` (relight / PTM light directions);
- ``trajectory.png`` (q, q̇, q̈ against the limits), ``path.png`` (the light's path on the sphere),
  ``landmarks_*.png`` (polar plot, histograms, camera images, cost map);
- ``preview.html`` (Meshcat, opens with no server) and ``report.md`` (the figures and key numbers).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from optlight.export import write_results
from optlight.viz.figures import save_landmark_figures
from optlight.viz.trajectory_figures import path_figure, trajectory_figure

if TYPE_CHECKING:
    from optlight.pipeline import Plan


def plan_dict(plan: Plan) -> dict[str, Any]:
    """What plan.json records besides the trajectory and the verification (which export adds)."""
    robot, spec = plan.robot, plan.problem.robot
    return {
        "problem": plan.problem.to_dict(),
        "problem_file": str(plan.problem.source) if plan.problem.source else None,
        "robot": {
            "name": robot.name,
            "joint_names": robot.joint_names,
            "light_offset_m": spec.light_offset_m,
            "light_rpy_deg": spec.light_rpy_deg,
            "base_position_m": spec.base_position_m,
            "base_rpy_deg": spec.base_rpy_deg,
            "lower": robot.lower,
            "upper": robot.upper,
            "velocity_limit": robot.velocity_limit * spec.velocity_scale,
            "acceleration_limit": robot.acceleration_limit,
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
            for i, (lm, theta) in enumerate(zip(plan.visited, plan.landmark_thetas, strict=True))
        ],
        "landmark_search": {
            "mode": plan.landmarks.mode,
            "reference": plan.landmarks.reference_label,
            "resolution": plan.landmarks.resolution,
            "iterations": plan.landmarks.iterations,
            "time_s": plan.landmarks.time_s,
        },
        "trajectory_nlp": {
            "status": plan.nlp.status,
            "success": plan.nlp.success,
            "cost": plan.nlp.cost,
            "iterations": plan.nlp.iterations,
            "max_h_residual_m": plan.nlp.max_h_residual,
            "time_s": plan.nlp.time_s,
            "knots": plan.path.n_knots,
            "landmark_knots": plan.path.landmark_knots,
        },
        "summary": plan.summary(),
        "warnings": list(plan.warnings),
    }


def report_markdown(plan: Plan, figures: Sequence[str]) -> str:
    """report.md: what was solved, the key numbers, the verification and the figures."""
    s = plan.summary()
    t = plan.timings
    lines = [
        f"# optlight plan: {plan.problem.name}",
        "",
        plan.problem.description,
        "",
        "Open `preview.html` in a browser for the 3-D preview (robot, object, light sphere, landmarks,",
        "path, camera; the trajectory plays as an animation).",
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
        plan.verification.summary(),
        "```",
        "",
    ]
    if plan.warnings:
        lines += ["## Warnings", "", *(f"- {w}" for w in plan.warnings), ""]
    lines += ["## Figures", ""]
    lines += [f"![{Path(f).stem}]({f})\n" for f in figures]
    return "\n".join(lines)


def save_plan(plan: Plan, folder: str | Path, *, overwrite: bool = False, preview: bool = True) -> list[Path]:
    """Write the results folder of a verified plan (see the module docstring); returns the paths.

    ``folder`` must be new, empty, or (with ``overwrite``) an earlier optlight output, of which only
    the files optlight wrote are replaced (the output policy of :mod:`optlight.export`)."""
    robot = plan.robot
    spec = plan.problem.robot
    timed = plan.trajectory.sample(plan.trajectory.sample_times(20.0))[0]
    figures = {
        "trajectory": trajectory_figure(
            plan.trajectory,
            lower=robot.lower,
            upper=robot.upper,
            velocity_limit=robot.velocity_limit * spec.velocity_scale,
            acceleration_limit=robot.acceleration_limit,
        ),
        "path": path_figure(
            plan.scene.sphere,
            plan.path.positions,
            np.array([robot.light_pose(q)[0] for q in timed]),
            np.array([lm.position for lm in plan.visited]),
        ),
    }

    def landmark_figures(folder: Path) -> list[Path]:
        return save_landmark_figures(plan.landmarks, plan.scene, folder)

    def preview_html(folder: Path) -> list[Path]:
        return [plan.preview().save_html(folder / "preview.html")]

    def report(folder: Path) -> list[Path]:
        names = sorted(p.name for p in folder.glob("*.png"))
        path = folder / "report.md"
        path.write_text(report_markdown(plan, names))
        return [path]

    writers = [landmark_figures, *([preview_html] if preview else []), report]
    return write_results(
        folder,
        trajectory=plan.trajectory,
        report=plan.verification,
        plan_dict=plan_dict(plan),
        joint_names=robot.joint_names,
        light_directions_camera=plan.light_directions_camera,
        image_pattern=plan.problem.trajectory.image_pattern,
        figures=figures,
        writers=writers,
        overwrite=overwrite,
    )
