"""Scene benchmark: G-buffer build, NumPy render, CasADi luminance value + gradient.

    python benchmarks/bench_scene.py [--json PATH] [--repeats N]

Measured on the default problem (procedural face): the G-buffer at 256² (Embree BVH build and
primary rays), the NumPy render at 256² once the G-buffer exists (with and without shadow rays),
and at 64² the CasADi luminance alone and the scalar objective J(a) = Σ I_i(a, v)² with its gradient
∂J/∂a (the shape of what an NLP evaluates). Each timing is repeated, light positions cycling over
the cap; the table gives median and 98th percentile wall-clock times in milliseconds.
:func:`run` returns the same numbers as a dict for a benchmark runner.
"""

from __future__ import annotations

import argparse
import platform
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import casadi as ca
import numpy as np

from optlight import load_problem
from optlight.export import write_json
from optlight.scene import Scene
from optlight.scene.gbuffer import RayCaster, build_gbuffer
from optlight.scene.luminance import luminance_function
from optlight.scene.objects import build_object

#: Targets of the scene: render ≤ 50 ms at 256² once the G-buffer exists, value+gradient ≤ 1 ms at 64².
TARGETS_MS = {"render_256_shadows": 50.0, "render_256_no_shadows": 50.0, "objective_value_gradient_64": 1.0}


def _timings(fn: Callable[[int], object], repeats: int) -> dict[str, float]:
    fn(0)  # warm-up: caches, lazy BVH builds, allocator
    samples = []
    for k in range(repeats):
        start = time.perf_counter()
        fn(k)
        samples.append(time.perf_counter() - start)
    ms = 1e3 * np.asarray(samples)
    return {"median_ms": float(np.median(ms)), "p98_ms": float(np.percentile(ms, 98)), "repeats": repeats}


def run(repeats: int = 30) -> dict[str, Any]:
    """Time the scene operations; returns {name: {median_ms, p98_ms, repeats[, target_ms]}, "meta": …}."""
    repeats = max(30, repeats)
    problem = load_problem("default")
    scene = Scene.from_problem(problem, 256, 256)
    lights = scene.sphere.position(np.full(16, 0.6), np.linspace(0, 2 * np.pi, 16, endpoint=False))
    results: dict[str, Any] = {}

    results["object_build"] = _timings(lambda k: build_object(problem), repeats)
    results["gbuffer_256"] = _timings(
        lambda k: build_gbuffer(scene.camera, scene.object, RayCaster(scene.mesh)), repeats
    )
    ones = np.ones(scene.gbuffer.size)
    results["render_256_no_shadows"] = _timings(
        lambda k: scene.to_image(scene.pixels(lights[k % 16], visibility=ones)), repeats
    )
    results["render_256_shadows"] = _timings(lambda k: scene.render(lights[k % 16]), repeats)
    results["shadow_rays_256"] = _timings(lambda k: scene.visibility(lights[k % 16]), repeats)

    small = Scene.from_problem(problem, 64, 64)
    visibilities = [ca.DM(small.visibility(a)) for a in lights]
    points = [ca.DM(a) for a in lights]
    f = small.luminance()
    a = ca.MX.sym("a", 3)
    v = ca.MX.sym("v", small.gbuffer.size)
    image = f(a, v)
    objective = ca.sumsqr(image)
    value_gradient = ca.Function("objective", [a, v], [objective, ca.gradient(objective, a)])
    results["luminance_value_64"] = _timings(lambda k: f(points[k % 16], visibilities[k % 16]), 10 * repeats)
    results["objective_value_gradient_64"] = _timings(
        lambda k: value_gradient(points[k % 16], visibilities[k % 16]), 10 * repeats
    )
    results["luminance_build_64"] = _timings(
        lambda k: luminance_function(small.gbuffer, small.light, small.sphere.center, small.sphere.radius),
        repeats,
    )
    for name, target in TARGETS_MS.items():
        results[name]["target_ms"] = target
    results["meta"] = {
        "triangles": len(scene.mesh.faces),
        "pixels_256": scene.gbuffer.size,
        "pixels_64": small.gbuffer.size,
        "python": platform.python_version(),
        "machine": platform.machine(),
    }
    return results


def _print(results: dict[str, Any]) -> None:
    rows = [(name, r) for name, r in results.items() if name != "meta"]
    meta = results["meta"]
    caption = f"{meta['triangles']} triangles; {meta['pixels_256']} object pixels at 256², {meta['pixels_64']} at 64²"
    try:
        from rich.console import Console
        from rich.table import Table
    except ImportError:
        print(caption)
        for name, r in rows:
            print(f"{name:32s} {r['median_ms']:9.3f} {r['p98_ms']:9.3f} {r.get('target_ms', '')}")
        return
    table = Table(title="optlight scene", caption=caption)
    for col in ("operation", "median ms", "p98 ms", "target ms", "repeats"):
        table.add_column(col, justify="left" if col == "operation" else "right")
    for name, r in rows:
        target = r.get("target_ms")
        ok = "" if target is None else (" ✓" if r["median_ms"] <= target else " ✗")
        table.add_row(
            name,
            f"{r['median_ms']:.3f}",
            f"{r['p98_ms']:.3f}",
            "" if target is None else f"{target:g}{ok}",
            str(r["repeats"]),
        )
    Console().print(table)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--json", type=Path, help="write the results to this file")
    parser.add_argument("--repeats", type=int, default=30, help="repetitions per timing (at least 30)")
    args = parser.parse_args()
    results = run(args.repeats)
    _print(results)
    if args.json:
        write_json(args.json, results)


if __name__ == "__main__":
    main()
