"""The ``optlight`` command.

Every subcommand takes PROBLEM as a path or the name of a file in ``problems/``. User mistakes
(an invalid problem file, an unreachable landmark, a plan that fails verification) are printed in
one line on stderr with exit status 2; no traceback.
"""

from __future__ import annotations

import argparse
import sys
import warnings
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np

from optlight.errors import OptlightError
from optlight.spec import available_problems, load_problem


def _cmd_check(args: argparse.Namespace) -> int:
    from optlight.setup import Setup

    # building the setup checks what the file alone cannot show (mesh, URDF and frame, reference
    # image, the camera's view of the object, the environment's layout)
    problem = Setup.from_problem(load_problem(args.problem)).problem
    print(f"{problem.source}: valid ({problem.description})")
    return 0


def _cmd_render(args: argparse.Namespace) -> int:
    from optlight.scene import Scene
    from optlight.viz.images import save_gray_png

    problem = load_problem(args.problem)
    scene = Scene.from_problem(problem)
    position = scene.sphere.position(np.deg2rad(args.zenith), np.deg2rad(args.azimuth))
    image = scene.render(position, noise=problem.light.noise_std > 0)
    path = save_gray_png(args.out, image, problem.light.saturation)
    print(f"wrote {path} (zenith {args.zenith:g}°, azimuth {args.azimuth:g}°)")
    return 0


def _cmd_solve(args: argparse.Namespace) -> int:
    from rich.console import Console
    from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn
    from rich.table import Table

    from optlight.pipeline import STAGES, solve

    console = Console(stderr=True)
    problem = load_problem(args.problem)
    out = Path(args.out) if args.out else Path("results") / problem.name
    with Progress(
        TextColumn("{task.description:<10}"),
        BarColumn(),
        TextColumn("{task.completed}/{task.total}"),
        TimeElapsedColumn(),
        console=console,
        transient=False,
    ) as bars:
        tasks = {name: bars.add_task(name, total=1, start=False) for name in STAGES}

        def progress(stage: str, done: int, total: int) -> None:
            bars.start_task(tasks[stage])
            bars.update(tasks[stage], completed=done, total=total)

        with warnings.catch_warnings(record=True):
            plan = solve(problem, progress=progress)
    table = Table(title=f"optlight solve {problem.name}", show_header=False)
    for key, value in _summary_rows(plan.summary()):
        table.add_row(key, value)
    console.print(table)
    for note in plan.warnings:
        console.print(f"[yellow]warning:[/yellow] {note}")
    if not plan.verification.passed:
        console.print(plan.verification.summary())
    with console.status(f"writing {out}/ (figures, preview, report)"):
        plan.save(out, overwrite=True)  # refuses (VerificationError) when verification failed
    console.print(f"results: {out}/  (report: {out / 'report.md'}, preview: {out / 'preview.html'})")
    if args.view:
        plan.preview().show()
    return 0


def _summary_rows(s: dict) -> list[tuple[str, str]]:
    return [
        ("robot", s["robot"]),
        ("landmarks", str(s["landmarks"])),
        ("mean landmark cost", f"{s['mean_landmark_cost']:.3g}"),
        ("path knots", str(s["knots"])),
        ("trajectory NLP", f"{s['nlp_status']} ({s['nlp_iterations']} iterations)"),
        ("max |h|", f"{s['max_h_residual_m']:.2e} m"),
        (
            "joint path (NLP / per-knot IK)",
            f"{s['joint_path_length_rad']:.3f} / {s['knot_ik_path_length_rad']:.3f} rad",
        ),
        ("duration", f"{s['duration_s']:.2f} s ({s['motion_time_s']:.2f} s moving)"),
        ("verification", "passed" if s["verification_passed"] else "FAILED"),
        ("solve time", f"{s['timings_s']['total']:.2f} s"),
    ]


def _cmd_reach(args: argparse.Namespace) -> int:
    from optlight.planning.reach import reachability_map
    from optlight.setup import Setup

    problem = load_problem(args.problem)
    setup = Setup.from_problem(problem)
    result = reachability_map(setup, zenith_step_deg=args.zenith_step, azimuth_step_deg=args.azimuth_step)
    png, js = result.save(args.out)
    print(f"{100 * result.reachable_fraction:.1f}% of the light cap reachable by {problem.robot.name}")
    if result.environment:
        print(f"{100 * result.taken_fraction:.1f}% of it taken by the environment (collision or view)")
    print(f"wrote {png} and {js}")
    return 0


def _cmd_batch(args: argparse.Namespace) -> int:
    from optlight.batch import run_batch

    result = run_batch(args.spec, args.out, scheduler=args.scheduler, workers=args.workers)
    skipped = f", {result.skipped} done before" if result.skipped else ""
    print(f"{result.ok} of {len(result.records)} rows solved ({result.failed} failed{skipped}) in {result.elapsed_s:.1f} s")
    for record in result.records:
        if record.status != "ok":
            print(f"failed {record.id}: {record.error}", file=sys.stderr)
    print(f"results: {result.table_md} and {result.table_csv}")
    return 1 if result.failed else 0


def _cmd_cell(args: argparse.Namespace) -> int:
    from optlight.cell import design_cell

    result = design_cell(args.spec, args.out, scheduler=args.scheduler, workers=args.workers)
    for line in result.summary_lines():
        print(line)
    return 0


def _cmd_problems(args: argparse.Namespace) -> int:
    problems = available_problems()
    width = max((len(n) for n in problems), default=0)
    for name, description in problems.items():
        print(f"{name:<{width}}  {description}")
    return 0


def _cmd_bench(args: argparse.Namespace) -> int:
    import importlib.util

    # the benchmarks live in the source repository, next to the package, not inside it
    runner = Path(__file__).resolve().parent.parent / "benchmarks" / "run.py"
    spec = importlib.util.spec_from_file_location("optlight_benchmarks.run", runner)
    if not runner.is_file() or spec is None or spec.loader is None:
        raise OptlightError(
            "the benchmarks live in the source repository's benchmarks/ folder, not in the installed "
            "package: clone the repository and run `optlight bench` (or `make bench`) there"
        )
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    return int(module.bench(args.names, quick=args.quick, out=Path(args.out) if args.out else None))


def build_parser() -> argparse.ArgumentParser:
    """The argument parser with one subparser per command."""
    parser = argparse.ArgumentParser(
        prog="optlight",
        description="Camera-driven robotic light source positioning.",
    )
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    def add(name: str, func: Callable[[argparse.Namespace], int], help: str) -> argparse.ArgumentParser:
        p = sub.add_parser(name, help=help, description=help)
        p.set_defaults(func=func)
        return p

    p = add("check", _cmd_check, "validate a problem file")
    p.add_argument("problem", help="problem file path or built-in name")
    p = add("solve", _cmd_solve, "solve a problem: landmarks, trajectory, verification, results folder")
    p.add_argument("problem", help="problem file path or built-in name")
    p.add_argument("--out", help="results folder (default: results/<problem name>)")
    p.add_argument(
        "--view", action="store_true", help="serve the live Meshcat preview on 127.0.0.1 afterwards"
    )
    p = add("reach", _cmd_reach, "map where on the light sphere the robot can put the light")
    p.add_argument("problem", help="problem file path or built-in name")
    p.add_argument("--out", required=True, help="output folder for reachability.png and reachability.json")
    p.add_argument("--zenith-step", type=float, default=5.0, help="grid step in zenith, degrees")
    p.add_argument("--azimuth-step", type=float, default=10.0, help="grid step in azimuth, degrees")
    p = add("render", _cmd_render, "render the camera image for one light position")
    p.add_argument("problem", help="problem file path or built-in name")
    p.add_argument("--zenith", type=float, required=True, help="light zenith, degrees from the camera axis")
    p.add_argument("--azimuth", type=float, required=True, help="light azimuth, degrees (90 = from above)")
    p.add_argument("--out", required=True, help="output PNG file")
    p = add("batch", _cmd_batch, "solve a batch of problems on a Dask cluster (exit status 1 if a row failed)")
    p.add_argument("spec", help="batch spec file (TOML): a base problem and a grid or list of overrides")
    p.add_argument("--out", required=True, help="output folder: plans/, records/, results.csv, results.md")
    _add_engine_arguments(p)
    p = add("cell", _cmd_cell, "search the robot's (and the camera's) placement for the most lights reached")
    p.add_argument("spec", help="cell spec file (TOML): a base problem and the ranges to search")
    p.add_argument("--out", required=True, help="output folder: heat map, candidates, best_problem.toml")
    _add_engine_arguments(p)
    add("problems", _cmd_problems, "list the built-in problems")
    p = add("bench", _cmd_bench, "run the benchmarks, print the table, write benchmarks/results/latest.*")
    p.add_argument("names", nargs="*", metavar="PROBLEM", help="problem or component benchmark; default: all")
    p.add_argument("--quick", action="store_true", help="reduced sizes and one solve per problem (CI)")
    p.add_argument("--out", metavar="DIR", help="output folder (default benchmarks/results)")
    return parser


def _add_engine_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--scheduler", metavar="ADDRESS", help="remote Dask scheduler (default: a local cluster on 127.0.0.1)"
    )
    p.add_argument("--workers", type=int, metavar="N", help="local cluster worker processes (default: one per core)")


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the console script; returns the exit status."""
    args = build_parser().parse_args(argv)
    try:
        return int(args.func(args))
    except OptlightError as e:
        print(f"optlight: error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("optlight: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
