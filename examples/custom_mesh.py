"""Custom mesh: light your own object.

A painted relief — an 18 cm square tile with bumps and a groove, vertex colours in stripes — is made
with trimesh and exported to PLY. A problem file next to it points at it (``[object] kind = "mesh"``,
``path = "relief.ply"``; the mesh's +z side faces the camera, +y is up). The example renders the
relief under a few lights (PNG, cast shadows included) and finds the landmarks whose histograms match
a 20° reference light.

Run (headless; ``--view`` also serves the live Meshcat preview on 127.0.0.1)::

    .venv/bin/python examples/custom_mesh.py [--landmarks 8] [--out DIR] [--view]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import trimesh

import optlight

#: The problem file written next to the mesh; ``{count}`` is the number of landmarks.
PROBLEM_TOML = """\
description = "Painted relief from examples/custom_mesh.py, Panda, {count} landmarks matching a 20° light"

[object]
kind = "mesh"
path = "relief.ply"
center_m = [0.35, 0.0, 0.45]

[camera]
position_m = [-0.343, -0.4, 0.45]
width = 128
height = 128
fov_deg = 20.0

[light_sphere]
radius_m = 0.40
zenith_max_deg = 60.0

[[objective.terms]]
kind = "histogram"
distance = "emd2"

[objective.reference]
kind = "light"
zenith_deg = 20.0
azimuth_deg = 45.0

[landmarks]
count = {count}
"""

#: Lights (zenith, azimuth) in degrees for the example renders.
RENDER_LIGHTS = ((0.0, 0.0), (45.0, 0.0), (45.0, 90.0), (45.0, 180.0), (45.0, 270.0))


def relief_mesh(size: float = 0.18, n: int = 91) -> trimesh.Trimesh:
    """A square height field z(x, y) (m) over [−size/2, size/2]², facing +z: Gaussian bumps and a
    diagonal groove, with grey and terracotta stripes as vertex colours."""
    x, y = np.meshgrid(np.linspace(-size / 2, size / 2, n), np.linspace(-size / 2, size / 2, n))
    bumps = ((-0.04, 0.04, 0.025), (0.035, 0.03, 0.02), (0.0, -0.035, 0.03), (0.05, -0.05, 0.015))
    z = np.zeros_like(x)
    for cx, cy, height in bumps:
        z += height * np.exp(-((x - cx) ** 2 + (y - cy) ** 2) / (2 * 0.011**2))
    z -= 0.01 * np.exp(-((x + y) ** 2) / (2 * 0.006**2))
    vertices = np.column_stack([x.ravel(), y.ravel(), z.ravel()])
    i = np.arange(n - 1)[:, None] * n + np.arange(n - 1)[None, :]  # lower-left corner of each cell
    i = i.ravel()
    faces = np.concatenate([np.column_stack([i, i + 1, i + n + 1]), np.column_stack([i, i + n + 1, i + n])])
    stripe = (np.floor((x.ravel() + size / 2) / 0.03) % 2).astype(bool)
    colors = np.where(stripe[:, None], [200, 120, 90, 255], [190, 190, 190, 255]).astype(np.uint8)
    return trimesh.Trimesh(vertices, faces, vertex_colors=colors, process=False)


def main() -> None:
    """Make the mesh and its problem, render it under a few lights, find the landmarks."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--landmarks", type=int, default=8, help="number of landmarks (azimuths)")
    parser.add_argument("--out", type=Path, default=Path("results/examples/custom_mesh"))
    parser.add_argument("--view", action="store_true", help="serve the live Meshcat preview")
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)

    mesh = relief_mesh()
    mesh_path = args.out / "relief.ply"
    mesh.export(mesh_path)
    problem_path = args.out / "problem.toml"
    problem_path.write_text(PROBLEM_TOML.format(count=args.landmarks))
    problem = optlight.load_problem(problem_path)
    print(
        f"wrote {mesh_path} ({len(mesh.vertices)} vertices, {len(mesh.faces)} triangles) and {problem_path}"
    )

    scene = optlight.Scene.from_problem(problem)
    saturation = problem.light.saturation
    print(
        f"the camera sees the relief on {scene.gbuffer.size} of "
        f"{scene.camera.width * scene.camera.height} pixels"
    )
    for zenith, azimuth in RENDER_LIGHTS:
        light = scene.sphere.position(np.deg2rad(zenith), np.deg2rad(azimuth))
        pixels = scene.pixels(light)
        shadowed = 1.0 - float(np.mean(scene.visibility(light)))
        path = optlight.save_gray_png(
            args.out / f"render_z{zenith:02.0f}_a{azimuth:03.0f}.png", scene.to_image(pixels), saturation
        )
        print(
            f"  {path}: mean {np.mean(pixels) / saturation:.3f}, "
            f"{100 * shadowed:.1f}% of the relief in cast shadow"
        )

    setup = optlight.Setup.from_problem(problem)
    landmarks = optlight.find_landmarks(
        setup.workcell, setup.image_costs, setup.landmark_spec, setup.solver, setup.file
    )
    print(
        f"{len(landmarks)} landmarks in {landmarks.time_s:.1f} s ({landmarks.iterations} IPOPT iterations):"
    )
    for lm in landmarks.landmarks:
        print(
            f"  azimuth {np.rad2deg(lm.azimuth):5.1f}°: zenith {np.rad2deg(lm.zenith):5.1f}°, "
            f"cost {lm.cost:.3g}"
        )

    if args.view:
        preview = optlight.Preview.at_best_landmark(scene, optlight.load_robot(problem), landmarks)
        if not preview.reached:
            print("the robot does not reach that landmark: shown at the closest pose it found")
        preview.show("light at the lowest-cost landmark")


if __name__ == "__main__":
    main()
