"""The dataset folder of an acquisition: the best round's images, captures.csv and lights.lp, every
round's (or, with the folder camera, every round's plan folder), the calibration, acquisition.json
and the README (docs/design.md §12)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from optlight.acquisition.rounds import round_folder
from optlight.capture import write_capture_png
from optlight.export import MANIFEST, library_versions, lp_direction, lp_text, write_captures
from optlight.jsondata import json_safe

if TYPE_CHECKING:
    from optlight.acquisition.result import Acquisition, Iteration


def write_dataset(acquisition: Acquisition, root: Path) -> list[str]:
    """Write the dataset folder's files into ``root`` (:meth:`Acquisition.save
    <optlight.acquisition.Acquisition.save>` lists them); return their names relative to it."""
    files: list[str] = []
    if acquisition.camera == "folder":
        plans = [it.plan for it in acquisition.iterations]
        plans += [acquisition.next_plan] if acquisition.next_plan else []
        for index, plan in enumerate(plans):
            written = plan.save(root / round_folder(index), preview=False)
            # a round folder carries its own manifest (a results folder of its own); the dataset's lists it too
            files += [str(Path(p).relative_to(root)) for p in written] + [f"{round_folder(index)}/{MANIFEST}"]
    else:
        for it in acquisition.iterations:
            sub = Path("iterations") / f"{it.index:02d}"
            files += [str(sub / f) for f in write_captures_folder(root / sub, it)]
    if acquisition.iterations:
        files += write_captures_folder(root, acquisition.best)
    calibration = acquisition.calibration
    if calibration is not None:
        scene = acquisition.setup.scene
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
    if acquisition.iterations:
        acquisition.figure().savefig(root / "measured_cost.png", dpi=120)
        files.append("measured_cost.png")
    (root / "README.md").write_text(acquisition.readme())
    files.append("README.md")
    document = {
        **acquisition.summary(),
        "problem_definition": acquisition.setup.problem.to_dict(),
        "exposure": acquisition.exposure,
        "loop": acquisition.setup.problem.to_dict().get("loop", {}),
        "world": acquisition.setup.problem.to_dict().get("world", {}),
        "iterations_detail": [it.to_dict() for it in acquisition.iterations],
        "versions": library_versions(),
        "files": [*files, "acquisition.json"],
    }
    (root / "acquisition.json").write_text(
        json.dumps(json_safe(document), indent=2, allow_nan=False) + "\n"
    )
    files.append("acquisition.json")
    return files


def write_captures_folder(folder: Path, iteration: Iteration) -> list[str]:
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
