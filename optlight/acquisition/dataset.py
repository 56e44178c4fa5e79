"""The files of an acquisition's dataset folder (docs/design.md §12): a round's images with its
captures.csv and lights.lp, each round's plan folder (the folder camera), the calibrated model, and
acquisition.json. :meth:`Acquisition.save <optlight.acquisition.Acquisition.save>` composes them."""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from optlight.acquisition.rounds import round_folder
from optlight.capture import Capture, write_capture_png
from optlight.capture.calibration import Calibration
from optlight.capture.lamp import LampCalibration
from optlight.export import MANIFEST, lp_direction, lp_text, write_captures
from optlight.jsondata import json_safe
from optlight.plan import Plan
from optlight.scene import Scene
from optlight.verify import capture_exposures


def write_round_plans(root: Path, plans: Sequence[Plan]) -> list[str]:
    """Each round's plan folder ``round_NN/`` (:meth:`Plan.save <optlight.plan.Plan.save>` without the
    preview); returns the names written, relative to ``root``."""
    files: list[str] = []
    for index, plan in enumerate(plans):
        written = plan.save(root / round_folder(index), preview=False)
        # a round folder carries its own manifest (a results folder of its own); the dataset's lists it too
        files += [str(Path(p).relative_to(root)) for p in written] + [f"{round_folder(index)}/{MANIFEST}"]
    return files


def write_calibration(root: Path, scene: Scene, calibration: Calibration) -> list[str]:
    """``calibration.json``, ``albedo_factor.npy`` (H, W; 1 where not calibrated) and, when
    recovered, ``normals.npy`` (H, W, 3, world frame, zeros where not recovered); returns the names."""
    (root / "calibration.json").write_text(json.dumps(json_safe(calibration.to_dict()), indent=2) + "\n")
    np.save(root / "albedo_factor.npy", scene.to_image(calibration.albedo_factor) + ~scene.gbuffer.mask)
    files = ["calibration.json", "albedo_factor.npy"]
    if calibration.normals is not None and calibration.normals_valid is not None:
        h, w = scene.gbuffer.mask.shape
        normals = np.zeros((h * w, 3))
        valid = calibration.normals_valid
        normals[scene.gbuffer.pixel_index[valid]] = calibration.normals[valid]
        np.save(root / "normals.npy", normals.reshape(h, w, 3))
        files.append("normals.npy")
    return files


def write_document(root: Path, document: dict[str, Any]) -> str:
    """``acquisition.json``, strict JSON (non-finite numbers as null); returns its name."""
    (root / "acquisition.json").write_text(json.dumps(json_safe(document), indent=2, allow_nan=False) + "\n")
    return "acquisition.json"


def write_captures_folder(
    folder: Path, plan: Plan, captures: Sequence[Capture], lamp: LampCalibration | None = None
) -> list[str]:
    """A round's images, captures.csv and lights.lp in ``folder``; returns the names written. The
    lights are where ``lamp`` (the calibrated lamp on the flange) puts them, a + R δ, for the
    captures whose light rotation is known; the nominal light frame's positions otherwise."""
    spec = plan.problem.trajectory
    folder.mkdir(parents=True, exist_ok=True)
    positions = np.array(
        [
            c.light_position if lamp is None or c.light_rotation is None else c.light_position + c.light_rotation @ lamp.offset_m
            for c in captures
        ]
    )
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
        exposures=capture_exposures(
            plan.trajectory, spec.settle_s, spec.exposure_s, plan.robot.light_pose, plan.setup.sphere.center
        ),
    )
    names = [spec.image_pattern.format(index=i) for i in range(len(captures))]
    for name, capture in zip(names, captures, strict=True):
        write_capture_png(folder / name, capture.image, plan.problem.light.saturation)
    (folder / "lights.lp").write_text(lp_text(names, lp_direction(directions)))
    return ["captures.csv", "lights.lp", *names]
