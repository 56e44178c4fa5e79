"""Light sets: design time, and the normal error of a designed set against the classical ring and a
random set, in the same run.

Design time (each repeat a fresh random start, the NLP built once per set size and reused):

- ``photometric_stereo`` N = 8, 48 and 64: :class:`optlight.planning.lightsets.PhotometricStereoTerm` on the
  default face at the design resolution (cast-shadow masks re-computed between solves);
- ``rti`` N = 48 and N = 64: :class:`optlight.planning.lightsets.RieszEnergy` (s = 4) on the cap, with the
  max-min separation and covering radius against a Fibonacci lattice and a random set;
- ``grid`` N = 64: the Yale B directions mapped onto a stand-in for the reachable-and-clear region
  (the cap minus a cone of 12° around the camera axis); requested vs achieved lights.

Normal error (on the model): for the default face and a self-shadowing relief (a plate with tall
Gaussian bumps, written as a mesh), N = 8 lights: the designed set, the classical ring (slant
arccos(1/√3) = 54.7356°, or the cap's edge when that is lower) and a random set uniform on the cap
(a new one per repeat), each rendered by the NumPy renderer with shadow rays and Gaussian noise
σ = ``NOISE`` (a new draw per repeat) at the evaluation resolution, recovered by least squares
(:func:`optlight.photometric_stereo.recover_from_scene`) and compared with the G-buffer normals
over the pixels all three sets recovered. Reported per set: the mean angular error (deg; median and
p98 over repeats), its p95 over pixels, the share of object pixels recovered (success %) and the
set's expected error (the objective at the evaluation resolution).

    python benchmarks/bench_lightsets.py [--repeats N] [--json PATH]
"""

from __future__ import annotations

import argparse
import math
import platform
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np
import trimesh

from optlight import load_problem
from optlight.export import write_json
from optlight.photometric_stereo import gbuffer_normal_map, recover_from_scene, render_set
from optlight.planning.lightsets import (
    CLASSICAL_SLANT,
    Cap,
    LightSetDesigner,
    PhotometricStereoTerm,
    RieszEnergy,
    angles_of,
    coverage,
    design_light_set,
    map_grid,
    ring_directions,
    yale_b_grid,
)
from optlight.scene import Scene
from optlight.spec import Problem, problem_from_dict

#: Lights of the photometric-stereo comparison.
N_PS = 8
#: Resolution (longer side, px) of the design and of the evaluation renders.
DESIGN_PX, EVAL_PX = 40, 96
#: Standard deviation of the sensor noise of the evaluation renders (normalised luminance).
NOISE = 0.01
#: Half-angle of the stand-in view cone excluded from the Yale grid's allowed region.
VIEW_CONE_DEG = 12.0


def _dist(values: list[float] | np.ndarray, success: list[bool] | None = None) -> dict[str, float]:
    v = np.asarray(values, float)
    out = {"median": float(np.median(v)), "p98": float(np.percentile(v, 98))}
    if success is not None:
        out["success_pct"] = 100.0 * float(np.mean(success))
    return out


def relief_problem(folder: Path) -> Problem:
    """The default problem with a self-shadowing relief instead of the face: a 0.16 m plate with
    nine Gaussian bumps 0.045 m tall and 0.01 m wide (slopes up to ~70°) (object frame, +z towards the camera)."""
    n = 121
    u = np.linspace(-0.08, 0.08, n)
    x, y = np.meshgrid(u, u)
    z = np.zeros_like(x)
    for cx in (-0.05, 0.0, 0.05):
        for cy in (-0.05, 0.0, 0.05):
            z += 0.045 * np.exp(-((x - cx) ** 2 + (y - cy) ** 2) / (2 * 0.01**2))
    vertices = np.column_stack([x.ravel(), y.ravel(), z.ravel()])
    i = np.arange(n - 1)[:, None] * n + np.arange(n - 1)[None, :]
    a, b, c, d = i.ravel(), i.ravel() + 1, i.ravel() + n, i.ravel() + n + 1
    faces = np.vstack([np.column_stack([a, b, d]), np.column_stack([a, d, c])])
    path = folder / "relief.ply"
    trimesh.Trimesh(vertices, faces, process=False).export(path)
    data = load_problem("default").to_dict()
    data["object"] = {**data["object"], "kind": "mesh", "path": str(path), "albedo": 0.7}
    data["object"].pop("face", None)
    return problem_from_dict(data)


def normal_errors(problem: Problem, repeats: int, seed: int) -> dict[str, Any]:
    """Designed vs ring vs random set on one object (module docstring). Each repeat renders the three
    sets with their own noise draws; errors are taken over the pixels all three recovered, so a set
    that leaves the hard pixels unrecovered is not credited for it (its recovered share is reported)."""
    problem = _with_noise(problem, NOISE)
    design = Scene.from_problem(problem, DESIGN_PX, DESIGN_PX)
    evaluate = Scene.from_problem(problem, EVAL_PX, EVAL_PX)
    cap = Cap.from_sphere(design.sphere)
    term = PhotometricStereoTerm.from_scene(design)
    judge = PhotometricStereoTerm.from_scene(evaluate)
    reference = gbuffer_normal_map(evaluate)
    t0 = time.perf_counter()
    designed = design_light_set(term, N_PS, cap, starts=4, seed=seed)
    design_s = time.perf_counter() - t0
    ring = ring_directions(N_PS, min(CLASSICAL_SLANT, cap.zenith_max))
    rng = np.random.default_rng(seed)
    names = ("designed", "ring", "random")
    rows: dict[str, dict[str, list[float]]] = {
        n: {"mean": [], "p95": [], "recovered": [], "expected": []} for n in names
    }
    for k in range(repeats):
        sets = {"designed": designed.directions, "ring": ring, "random": cap.random(N_PS, rng)}
        recoveries = {}
        for i, (name, directions) in enumerate(sets.items()):
            noise = np.random.default_rng([seed, k, i])
            images = render_set(evaluate, directions, noise=noise)
            recoveries[name] = recover_from_scene(evaluate, directions, images)
        common = np.logical_and.reduce([r.valid for r in recoveries.values()])
        for name, recovery in recoveries.items():
            error = recovery.angular_error(reference)[common]
            rows[name]["mean"].append(float(error.mean()))
            rows[name]["p95"].append(float(np.percentile(error, 95)))
            rows[name]["recovered"].append(recovery.error_stats(reference)["recovered_pct"])
            rows[name]["expected"].append(judge.numpy(sets[name]))
    out: dict[str, Any] = {
        name: {
            "mean_error_deg": {**_dist(r["mean"]), "success_pct": float(np.median(r["recovered"]))},
            "p95_error_deg": _dist(r["p95"]),
            "expected_error": float(np.median(r["expected"])),
        }
        for name, r in rows.items()
    }
    out["designed_over_ring"] = (
        out["designed"]["mean_error_deg"]["median"] / out["ring"]["mean_error_deg"]["median"]
    )
    out["designed_zenith_deg"] = np.degrees(designed.zenith).round(2).tolist()
    out["designed_azimuth_deg"] = np.degrees(designed.azimuth).round(2).tolist()
    out["design_time_s"] = design_s
    out["pixels"] = {"design": design.gbuffer.size, "evaluation": evaluate.gbuffer.size}
    return out


def _with_noise(problem: Problem, sigma: float) -> Problem:
    data = problem.to_dict()
    data["light"] = {**data["light"], "noise_std": sigma}
    return problem_from_dict(data, source=problem.source)


def design_times(repeats: int) -> dict[str, Any]:
    """Design time per set kind and size (module docstring)."""
    problem = load_problem("default")
    scene = Scene.from_problem(problem, DESIGN_PX, DESIGN_PX)
    cap = Cap.from_sphere(scene.sphere)
    out: dict[str, Any] = {}

    term = PhotometricStereoTerm.from_scene(scene)
    for n in (N_PS, 48, 64):
        t0 = time.perf_counter()
        designer = LightSetDesigner(term, n, cap)
        build = time.perf_counter() - t0
        times, ok, iterations = [], [], []
        for k in range(repeats):
            t0 = time.perf_counter()
            r = design_light_set(term, n, cap, starts=1, seed=k, designer=designer)
            times.append(time.perf_counter() - t0)
            ok.append(r.success)
            iterations.append(r.iterations)
        out[f"photometric_stereo_{n}"] = {
            "time_s": _dist(times, ok),
            "iterations": _dist(iterations),
            "build_s": build,
        }

    riesz = RieszEnergy()
    for n in (48, 64):
        designer = LightSetDesigner(riesz, n, cap)
        times, ok, separation, covering = [], [], [], []
        for k in range(repeats):
            t0 = time.perf_counter()
            r = design_light_set(riesz, n, cap, starts=1, seed=k, designer=designer)
            times.append(time.perf_counter() - t0)
            ok.append(r.success)
            c = coverage(r.directions, cap)
            separation.append(c["min_separation_deg"])
            covering.append(c["covering_radius_deg"])
        random_set = coverage(cap.random(n, np.random.default_rng(0)), cap)
        out[f"rti_{n}"] = {
            "time_s": _dist(times, ok),
            "min_separation_deg": _dist(separation),
            "covering_radius_deg": _dist(covering),
            "lattice": coverage(cap.lattice(n), cap),
            "random": random_set,
        }

    grid = yale_b_grid()

    def allowed(d: np.ndarray) -> np.ndarray:
        return angles_of(d)[0] > math.radians(VIEW_CONE_DEG)

    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        mapping = map_grid(grid, cap, allowed)
        times.append(time.perf_counter() - t0)
    out["grid_64"] = {
        "time_s": _dist(times, [True] * repeats),
        "requested": len(grid.names),
        "achieved_exactly": len(grid.names) - mapping.replaced_count,
        "replaced_pct": 100.0 * mapping.replaced_count / len(grid.names),
        "max_moved_deg": math.degrees(float(mapping.moved.max())),
    }
    return out


def run(repeats: int = 5) -> dict[str, Any]:
    """Design times and normal errors; returns the machine-readable results."""
    repeats = max(1, repeats)
    results: dict[str, Any] = {"design": design_times(repeats)}
    with tempfile.TemporaryDirectory() as folder:
        results["normal_error"] = {
            "face": normal_errors(load_problem("default"), repeats, seed=0),
            "relief": normal_errors(relief_problem(Path(folder)), repeats, seed=0),
        }
    results["meta"] = {
        "lights": N_PS,
        "noise_std": NOISE,
        "design_px": DESIGN_PX,
        "evaluation_px": EVAL_PX,
        "python": platform.python_version(),
        "machine": platform.machine(),
    }
    return results


def _print(results: dict[str, Any]) -> None:
    for name, r in results["design"].items():
        t = r["time_s"]
        print(
            f"design {name:24s} median {t['median']:8.3f} s  p98 {t['p98']:8.3f} s  success {t['success_pct']:.0f} %"
        )
    g = results["design"]["grid_64"]
    print(f"yale grid: {g['achieved_exactly']}/{g['requested']} exact, {g['replaced_pct']:.0f} % replaced")
    for obj, r in results["normal_error"].items():
        for name in ("designed", "ring", "random"):
            e = r[name]["mean_error_deg"]
            print(
                f"{obj:7s} {name:9s} mean error {e['median']:7.3f}° (p98 {e['p98']:7.3f}°), "
                f"recovered {e['success_pct']:5.1f} %, expected error {r[name]['expected_error']:.3f}"
            )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--repeats", type=int, default=5, help="repeats per measurement")
    parser.add_argument("--json", type=Path, help="write the results to this file")
    args = parser.parse_args()
    results = run(args.repeats)
    _print(results)
    if args.json:
        write_json(args.json, results)


if __name__ == "__main__":
    main()
