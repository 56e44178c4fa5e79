"""Reference-image objective: find the light that made a photograph.

The procedural face is rendered with the light at a known zenith and azimuth, with Gaussian sensor
noise, and written as an 8-bit PNG — a stand-in for a photograph taken under an unknown light. A
problem whose objective compares each rendered image with that PNG (per-pixel difference plus a
histogram term; ``[objective.reference] kind = "image"``, free landmarks) is then searched, and the
best landmark should recover the light that made the image: the angle between the two light
directions is printed. The best landmark's render is written next to the reference.

Run (headless; ``--view`` also serves the live Meshcat preview on 127.0.0.1)::

    .venv/bin/python examples/reference_image.py [--zenith 33] [--azimuth 223] [--landmarks 3] \
        [--out DIR] [--view]
"""

from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

import optlight


def angle_deg(a: NDArray[np.float64], b: NDArray[np.float64], center: NDArray[np.float64]) -> float:
    """Angle (deg) between the directions from ``center`` to the points ``a`` and ``b``."""
    u, v = a - center, b - center
    return float(np.rad2deg(np.arccos(np.clip(u @ v / np.linalg.norm(u) / np.linalg.norm(v), -1.0, 1.0))))


def main() -> None:
    """Render the reference, search the landmarks against it, print how close the best one is."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--zenith", type=float, default=33.0, help="zenith of the reference light (deg)")
    parser.add_argument("--azimuth", type=float, default=223.0, help="azimuth of the reference light (deg)")
    parser.add_argument("--noise", type=float, default=0.01, help="sensor noise σ (fraction of saturation)")
    parser.add_argument("--landmarks", type=int, default=3, help="number of free landmarks (1–3 is enough)")
    parser.add_argument("--out", type=Path, default=Path("results/examples/reference_image"))
    parser.add_argument("--view", action="store_true", help="serve the live Meshcat preview")
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)

    # The built-in reference-image problem (face, panda, image + histogram terms, free landmarks),
    # used here for its layout and objective; its own reference photograph is replaced below.
    base = optlight.load_problem("reference_image")
    scene = optlight.Scene.from_problem(base)
    saturation = base.light.saturation

    truth = scene.sphere.position(np.deg2rad(args.zenith), np.deg2rad(args.azimuth))
    rng = np.random.default_rng(7)
    image = scene.render(truth) + rng.normal(
        0.0, args.noise * saturation, (scene.camera.height, scene.camera.width)
    )
    reference = optlight.save_gray_png(args.out / "reference.png", image, saturation)
    print(
        f"reference image {reference}: light at zenith {args.zenith:g}°, azimuth {args.azimuth:g}°, "
        f"noise σ {args.noise:g}"
    )

    problem = dataclasses.replace(
        base,
        description=f"the light that made {reference.name}, from its image and histogram",
        objective=dataclasses.replace(
            base.objective,
            reference=dataclasses.replace(
                base.objective.reference, kind="image", image=str(reference.resolve())
            ),
        ),
        landmarks=dataclasses.replace(base.landmarks, mode="free", count=args.landmarks),
    )
    setup = optlight.Setup.from_problem(problem)
    landmarks = optlight.find_landmarks(
        setup.workcell, setup.image_costs, setup.landmark_spec, setup.solver, setup.file
    )
    print(
        f"{len(landmarks)} free landmarks in {landmarks.time_s:.1f} s "
        f"({landmarks.iterations} IPOPT iterations), in search order:"
    )
    for lm in landmarks.landmarks:
        error = angle_deg(lm.position, truth, scene.sphere.center)
        print(
            f"  zenith {np.rad2deg(lm.zenith):5.1f}°, azimuth {np.rad2deg(lm.azimuth):5.1f}°, "
            f"cost {lm.cost:.3g} ({lm.status}), {error:5.2f}° from the reference light"
        )

    best = min(landmarks.landmarks, key=lambda lm: lm.cost)
    error = angle_deg(best.position, truth, scene.sphere.center)
    print(f"best landmark recovers the reference light within {error:.2f}°")
    print(f"wrote {optlight.save_gray_png(args.out / 'best.png', scene.render(best.position), saturation)}")

    if args.view:
        preview = optlight.Preview.at_best_landmark(scene, optlight.load_robot(problem), landmarks)
        if not preview.reached:
            print("the robot does not reach that landmark: shown at the closest pose it found")
        preview.show("robot holding the light at the best landmark")


if __name__ == "__main__":
    main()
