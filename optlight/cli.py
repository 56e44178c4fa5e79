"""The ``optlight`` command.

Every subcommand takes PROBLEM as a path or the name of a file in ``problems/``. Each checks what
it will touch before any work: its arguments (finite, in range), its output location (the policy of
:mod:`optlight.export`: never over files optlight did not write; an earlier output only with
``--force``), then the problem file and everything built from it, built once
(:func:`optlight.preflight.preflight` builds the :class:`~optlight.setup.Setup` that ``solve`` and
``reach`` then use; ``render`` builds only the scene).
User mistakes (an invalid argument, problem file or output location, an unreachable landmark, a plan
that fails verification) are printed in one line on stderr with exit status 2, no traceback; progress
and results go to stdout.

Ctrl-C (SIGINT), SIGTERM and SIGHUP stop any command the same way, at any moment
(:mod:`optlight.interrupts`): the staging folder of an output not yet in place is removed, worker
processes and a local Dask cluster are stopped, one line is printed on stderr (``optlight:
interrupted``, ``optlight: terminated``, ``optlight: hung up``) and the exit status is 128 + the
signal's number (130, 143, 129). No partial output is left, and no process of the command outlives it.
"""

from __future__ import annotations

import argparse
import importlib
import logging
import math
import os
import signal
import sys
import warnings
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import NoReturn

import numpy as np

from optlight import interrupts
from optlight.errors import OptlightError, UsageError, VerificationError
from optlight.spec import available_problems, load_problem, resolve_problem_path

#: What ``--force`` allows, as the output policy's errors say it.
FORCE = "--force"
#: Smallest grid step of ``optlight reach`` (degrees): finer grids mean millions of IK solves.
MIN_STEP_DEG = 0.1
#: Most worker processes of a local cluster (``batch``, ``cell``).
MAX_WORKERS = 1024
#: What each command imports, up front and with Ctrl-C deferred: an interrupt in the middle of an
#: import can break a library for the rest of the run (trimesh catches it while importing an optional
#: part and leaves an error wrapper where a class should be).
MODULES = {
    "check": ("optlight.preflight",),
    "render": ("optlight.scene", "optlight.export", "optlight.viz.images"),
    "reach": ("optlight.preflight", "optlight.export", "optlight.planning.reach"),
    "acquire": ("optlight.preflight", "optlight.export", "optlight.acquisition", "rich.console"),
    "batch": ("optlight.batch", "rich.progress"),
    "cell": ("optlight.cell", "optlight.export", "rich.progress"),
    "solve": ("optlight.export", "optlight.viz.drawing", "rich.progress", "rich.table"),
}
#: What ``solve`` imports once its figure worker has started: the worker's own imports (~0.8 s of a
#: core) then overlap these and the problem's build, which leave a core idle, instead of taking
#: one from the landmark search (0.5 → 0.9 s on the default problem when they did).
SOLVE_MODULES = ("optlight.preflight", "optlight.pipeline", "optlight.report", "optlight.viz.preview")


def _import(modules: Sequence[str]) -> None:
    """Import ``modules`` with the stop signals deferred (see :data:`MODULES`)."""
    with interrupts.deferred():
        interrupts.reached("imports")
        for module in modules:
            importlib.import_module(module)


def _cmd_check(args: argparse.Namespace) -> int:
    from optlight.preflight import preflight

    problem = load_problem(args.problem)
    preflight(problem)  # builds the Setup: the check of what the file alone cannot show
    print(f"{problem.source}: valid ({problem.description})")
    return 0


def _cmd_render(args: argparse.Namespace) -> int:
    from optlight.export import check_output_file, write_file
    from optlight.scene import Scene
    from optlight.viz.images import save_gray_png

    if Path(args.out).suffix.lower() != ".png":
        raise UsageError("--out", f"{args.out}: expected a .png file name")
    check_output_file(args.out, overwrite=args.force, option="--out", force=FORCE)
    problem = load_problem(args.problem)
    scene = Scene.from_problem(problem)  # all a render needs (and the check of the object and camera)
    position = scene.sphere.position(np.deg2rad(args.zenith), np.deg2rad(args.azimuth))
    image = scene.render(position, noise=problem.light.noise_std > 0)
    path = write_file(
        args.out,
        lambda tmp: save_gray_png(tmp, image, problem.light.saturation),
        overwrite=args.force,
        option="--out",
        force=FORCE,
    )
    print(f"wrote {path} (zenith {args.zenith:g}°, azimuth {args.azimuth:g}°)")
    return 0


def _cmd_solve(args: argparse.Namespace) -> int:
    from rich.console import Console
    from rich.markup import escape
    from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn
    from rich.table import Table

    from optlight.export import check_output_folder
    from optlight.viz.drawing import FigureWorker

    out = Path(args.out) if args.out else Path("results") / resolve_problem_path(args.problem).stem
    check_output_folder(out, overwrite=args.force, option="--out", force=FORCE)
    problem = load_problem(args.problem)
    console = Console()  # stdout: stderr carries only the one-line error of a failed run
    # The figures are drawn in a process of their own, started once the output folder and the
    # problem file have passed their checks and before the heavy imports (SOLVE_MODULES); it draws
    # while this process solves and writes the exports and the preview.
    with FigureWorker() as worker:
        interrupts.reached("figure-worker")
        _import(SOLVE_MODULES)
        from optlight.pipeline import STAGES, solve
        from optlight.preflight import preflight

        with console.status("building the scene, objectives, robot and environment"):
            setup = preflight(problem)  # built once: the solve below takes it as it is
        interrupts.reached("setup")
        with Progress(
            TextColumn("{task.description:<10}"),
            BarColumn(),
            TextColumn("{task.completed}/{task.total}"),
            TimeElapsedColumn(),
            console=console,
            transient=False,
        ) as bars:
            # the scene was built above, in the checks: the solve has no "scene" stage to show
            tasks = {name: bars.add_task(name, total=1, start=False) for name in STAGES if name != "scene"}

            def progress(stage: str, done: int, total: int) -> None:
                interrupts.check()  # a Ctrl-C that IPOPT turned into "User_Requested_Stop"
                interrupts.reached(stage)
                bars.start_task(tasks[stage])
                bars.update(tasks[stage], completed=done, total=total)

            with warnings.catch_warnings(record=True):
                plan = solve(setup, progress=progress, worker=worker)
        interrupts.check()
        table = Table(title=f"optlight solve {problem.name}", show_header=False)
        for key, value in _summary_rows(plan.summary()):
            table.add_row(escape(key), escape(value))
        console.print(table)
        for note in plan.warnings:
            # escaped: notes name problem-file sections ("[landmarks] allow_partial"), not rich markup
            console.print(f"[yellow]warning:[/yellow] {escape(note)}")
        if not plan.verification.passed:
            console.print(escape(plan.verification.summary()))
        with console.status(f"writing {out}/ (figures, preview, report)"):
            plan.save(out, overwrite=args.force, worker=worker)  # refused (VerificationError) unless verified
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


def _cmd_acquire(args: argparse.Namespace) -> int:
    from rich.console import Console
    from rich.markup import escape

    from optlight.acquisition import acquire
    from optlight.export import check_output_folder
    from optlight.preflight import preflight

    if args.camera == "folder" and args.images is None:
        raise UsageError("--images", "the folder camera (--camera folder) needs the folder of the captured images")
    out = Path(args.out)
    check_output_folder(out, overwrite=args.force, option="--out", force=FORCE)
    problem = load_problem(args.problem)
    console = Console()  # stdout: stderr carries only the one-line error of a failed run
    with console.status("building the scene, objectives, robot and environment"):
        setup = preflight(problem)  # built once: the loop's first plan uses it as it is
    with console.status("") as status:

        def progress(iteration: int, stage: str, done: int, total: int) -> None:
            interrupts.check()  # a Ctrl-C that IPOPT turned into "User_Requested_Stop"
            status.update(f"iteration {iteration}: {stage} {done}/{total}")

        with warnings.catch_warnings(record=True):
            acquisition = acquire(setup, args.camera, images=args.images, progress=progress)
    interrupts.check()
    for it in acquisition.iterations:
        console.print(
            f"iteration {it.index}: measured cost {it.measured_cost:.4g}, modelled {it.modelled_cost:.4g}, "
            f"{it.wall_time_s:.1f} s"
        )
    calibration = acquisition.calibration
    if calibration is not None:
        console.print(
            f"calibrated model: {calibration.light_model} light, power {calibration.power:.3g}, ambient "
            f"{calibration.ambient:.3g}, camera response γ {calibration.gamma:.3g} (calibration.json)"
        )
    best = acquisition.best
    console.print(  # escaped: a failed re-plan's status names problem-file sections, not rich markup
        f"{escape(acquisition.status)}; best: iteration {best.index}, measured cost {best.measured_cost:.4g} "
        f"({best.measured_cost / max(acquisition.open_loop.measured_cost, 1e-300):.2f} × the open loop's)"
    )
    with console.status(f"writing {out}/"):
        acquisition.save(out, overwrite=args.force)
    console.print(f"dataset: {out}/  (acquisition.json, captures.csv, lights.lp, measured_cost.png)")
    return 0


def _cmd_reach(args: argparse.Namespace) -> int:
    from optlight.export import check_output_folder, write_folder
    from optlight.planning.reach import reachability_map
    from optlight.preflight import preflight

    check_output_folder(args.out, overwrite=args.force, option="--out", force=FORCE)
    problem = load_problem(args.problem)
    setup = preflight(problem)
    result = reachability_map(setup, zenith_step_deg=args.zenith_step, azimuth_step_deg=args.azimuth_step)
    interrupts.check()
    png, js = write_folder(
        args.out, lambda folder: result.save(folder), overwrite=args.force, option="--out", force=FORCE
    )
    print(f"{100 * result.reachable_fraction:.1f}% of the light cap reachable by {problem.robot.name}")
    if result.environment:
        print(f"{100 * result.taken_fraction:.1f}% of it taken by the environment (collision or view)")
    print(f"wrote {png} and {js}")
    return 0


def _cmd_batch(args: argparse.Namespace) -> int:
    from optlight.batch import check_batch_folder, run_batch

    check_batch_folder(Path(args.out), option="--out")  # first: new, empty or an earlier batch's
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
    from optlight.export import check_output_folder

    check_output_folder(args.out, overwrite=args.force, option="--out", force=FORCE)  # before any work
    result = design_cell(args.spec, args.out, scheduler=args.scheduler, workers=args.workers, overwrite=args.force)
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


class _Parser(argparse.ArgumentParser):
    """An argument parser whose errors are one-line :class:`UsageError` (no usage block)."""

    def error(self, message: str) -> NoReturn:
        raise UsageError(self.prog, f"{message} (see {self.prog} --help)")


def number(lo: float, hi: float, unit: str, *, lo_open: bool = False) -> Callable[[str], float]:
    """An argparse ``type``: a finite number in [lo, hi] (or (lo, hi] with ``lo_open``) in ``unit``,
    refused in one line that echoes the text as given."""
    interval = f"{'(' if lo_open else '['}{lo:g}, {hi:g}]"

    def parse(text: str) -> float:
        try:
            x = float(text)
        except ValueError:
            x = math.nan
        if not (math.isfinite(x) and (lo < x if lo_open else lo <= x) and x <= hi):
            raise argparse.ArgumentTypeError(f"expected a finite number of {unit} in {interval}, got {text}")
        return x

    return parse


def integer(lo: int, hi: int, unit: str) -> Callable[[str], int]:
    """An argparse ``type``: an integer number of ``unit`` in [lo, hi], refused in one line that
    echoes the text as given."""

    def parse(text: str) -> int:
        try:
            n = int(text)
        except ValueError:
            n = lo - 1
        if not lo <= n <= hi:
            raise argparse.ArgumentTypeError(f"expected an integer number of {unit} in [{lo}, {hi}], got {text}")
        return n

    return parse


def build_parser() -> argparse.ArgumentParser:
    """The argument parser with one subparser per command."""
    parser = _Parser(
        prog="optlight",
        description="Camera-driven robotic light source positioning.",
    )
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    force_help = "replace the output of an earlier optlight run there (only the files optlight wrote)"

    def add(name: str, func: Callable[[argparse.Namespace], int], help: str) -> argparse.ArgumentParser:
        p = sub.add_parser(name, help=help, description=help)
        p.set_defaults(func=func)
        return p

    p = add("check", _cmd_check, "validate a problem file")
    p.add_argument("problem", help="problem file path or built-in name")
    p = add("solve", _cmd_solve, "solve a problem: landmarks, trajectory, verification, results folder")
    p.add_argument("problem", help="problem file path or built-in name")
    p.add_argument("--out", help="results folder, new or empty (default: results/<problem name>)")
    p.add_argument("--force", action="store_true", help=force_help)
    p.add_argument(
        "--view", action="store_true", help="serve the live Meshcat preview on 127.0.0.1 afterwards"
    )
    p = add("acquire", _cmd_acquire, "camera in the loop: plan, capture, calibrate, re-plan; write the dataset")
    p.add_argument("problem", help="problem file path or built-in name")
    p.add_argument("--camera", choices=("model", "mitsuba", "folder"), default="model", help="what captures")
    p.add_argument("--images", help="folder with captures.csv and the images (--camera folder)")
    p.add_argument("--out", required=True, help="dataset folder, new or empty")
    p.add_argument("--force", action="store_true", help=force_help)
    p = add("reach", _cmd_reach, "map where on the light sphere the robot can put the light")
    p.add_argument("problem", help="problem file path or built-in name")
    p.add_argument(
        "--out", required=True, help="output folder, new or empty, for reachability.png and reachability.json"
    )
    p.add_argument("--force", action="store_true", help=force_help)
    p.add_argument(
        "--zenith-step",
        type=number(MIN_STEP_DEG, 90.0, "degrees"),
        default=5.0,
        help="grid step in zenith, degrees",
    )
    p.add_argument(
        "--azimuth-step",
        type=number(MIN_STEP_DEG, 360.0, "degrees"),
        default=10.0,
        help="grid step in azimuth, degrees",
    )
    p = add("render", _cmd_render, "render the camera image for one light position")
    p.add_argument("problem", help="problem file path or built-in name")
    p.add_argument(
        "--zenith",
        type=number(0.0, 180.0, "degrees"),
        required=True,
        help="light zenith, degrees from the camera axis",
    )
    p.add_argument(
        "--azimuth",
        type=number(-360.0, 360.0, "degrees"),
        required=True,
        help="light azimuth, degrees (90 = from above)",
    )
    p.add_argument("--out", required=True, help="output PNG file (not an existing one unless --force)")
    p.add_argument("--force", action="store_true", help="replace an existing PNG file")
    p = add("batch", _cmd_batch, "solve a batch of problems on a Dask cluster (exit status 1 if a row failed)")
    p.add_argument("spec", help="batch spec file (TOML): a base problem and a grid or list of overrides")
    p.add_argument(
        "--out",
        required=True,
        help="output folder, new or empty, or an earlier batch's (resumed): plans/, records/, results.csv, results.md",
    )
    _add_engine_arguments(p)
    p = add("cell", _cmd_cell, "search the robot's (and the camera's) placement for the most lights reached")
    p.add_argument("spec", help="cell spec file (TOML): a base problem and the ranges to search")
    p.add_argument(
        "--out", required=True, help="output folder, new or empty: heat map, candidates, best_problem.toml, best_plan/"
    )
    p.add_argument("--force", action="store_true", help=force_help)
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
    p.add_argument(
        "--workers",
        type=integer(1, MAX_WORKERS, "worker processes"),
        metavar="N",
        help="local cluster worker processes (default: one per core)",
    )


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the console script; returns the exit status (0, 2 for a user mistake, 128 +
    the signal's number after one of :data:`optlight.interrupts.SIGNALS`: 130 after Ctrl-C, 143
    after SIGTERM, 129 after SIGHUP).

    As the console script (``argv`` None) it ends the process itself once the command is done:
    the stop signals blocked, streams flushed, ``os._exit``. A signal in Python's own shutdown
    (atexit callbacks, freeing the libraries) would otherwise print "Exception ignored …
    KeyboardInterrupt" or kill the process with the signal instead of the exit status of the
    finished command.
    """
    # Libraries' log records (trimesh's "unable to use sparse matrix, falling back!" with a traceback)
    # are not for the user: without a handler Python would print warnings and worse on stderr.
    root = logging.getLogger()
    if not any(isinstance(h, logging.NullHandler) for h in root.handlers):
        root.addHandler(logging.NullHandler())
    with interrupts.latched():
        try:
            code = _run(argv)
            interrupts.reached("done")
        except KeyboardInterrupt:  # landed after _run's own handlers
            code = _interrupted()
        finally:
            if argv is None and interrupts.in_main_thread():
                signal.pthread_sigmask(signal.SIG_BLOCK, set(interrupts.SIGNALS))
    if argv is None:
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(code)
    return code


def _run(argv: Sequence[str] | None) -> int:
    """Parse the arguments, import what the command needs (signals deferred), run it."""
    try:
        args = build_parser().parse_args(argv)
        _import(MODULES.get(args.command, ()))
        return int(args.func(args))
    except OptlightError as e:
        if interrupts.pending():  # it came of a signal IPOPT swallowed (a failed NLP): the signal wins
            return _interrupted()
        # a failed verification's report lines follow the first; any other error is one line
        text = str(e) if isinstance(e, VerificationError) else " ".join(str(e).split())
        print(f"optlight: error: {text}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return _interrupted()
    except Exception:
        if interrupts.pending():  # a library turned the interrupt into its own error (CasADi: RuntimeError)
            return _interrupted()
        raise


def _interrupted() -> int:
    """Say which signal stopped the command, in one line; its exit status (128 + its number)."""
    signum = interrupts.received()
    try:
        print(f"optlight: {interrupts.SIGNALS[signum]}", file=sys.stderr)
    except OSError:  # no terminal left to tell (SIGHUP: it was closed)
        pass
    return interrupts.exit_status(signum)


if __name__ == "__main__":
    sys.exit(main())
