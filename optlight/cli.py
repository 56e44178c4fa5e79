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
import shlex
import signal
import sys
import warnings
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import NoReturn

import numpy as np

from optlight import interrupts, locks
from optlight.errors import OptlightError, UsageError, VerificationError
from optlight.spec import Problem, available_problems, load_problem, resolve_problem_path
from optlight.threads import WORKERS_PER_CORE, max_local_workers

#: What ``--force`` allows, as the output policy's errors say it.
FORCE = "--force"
#: Smallest grid step of ``optlight reach`` (degrees): finer grids mean millions of IK solves.
MIN_STEP_DEG = 0.1
#: Most cells of an ``optlight reach`` grid: one generalized IK solve (and a clear-posture search)
#: each, a few milliseconds to a second when the cell is out of reach.
MAX_REACH_CELLS = 20_000
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
    "simulate": ("optlight.export", "optlight.simulation"),
}
#: What ``solve`` imports once its figure worker has started: the worker's own imports (~0.8 s of a
#: core) then overlap these and the problem's build, which leave a core idle, instead of taking
#: one from the landmark search (which they would slow by ~80 % on the default problem).
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
    from optlight.viz.images import save_gray_png, written_by_optlight

    if Path(args.out).suffix.lower() != ".png":
        raise UsageError("--out", f"{args.out}: expected a .png file name")
    check_output_file(args.out, overwrite=args.force, option="--out", force=FORCE, ours=written_by_optlight)
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
        ours=written_by_optlight,
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
        from optlight.report import FigureDrafts

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

            drafts = FigureDrafts(worker)  # the figures drawn as the stages finish
            with warnings.catch_warnings(record=True):
                plan = solve(setup, progress=progress, on_stage=drafts)
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
            # refused (VerificationError) unless verified
            plan.save(out, overwrite=args.force, worker=worker, drawn=drafts.figures)
    console.print(f"results: {out}/  (report: {out / 'report.md'}, preview: {out / 'preview.html'})")
    if args.view:
        plan.preview().show()
    return 0


def _summary_rows(s: dict) -> list[tuple[str, str]]:
    bound = s["motion_bound"]
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
        (
            "moving / rest-to-rest bound",
            f"{bound['motion_time_s']:.2f} / {bound['rest_to_rest_s']:.2f} s ({bound['ratio']:.2f}×)",
        ),
        *(
            [("moving / flying bound", f"{bound['motion_time_s']:.2f} / {bound['flying_s']:.2f} s ({bound['flying_ratio']:.2f}×)")]
            if "flying_s" in bound
            else []
        ),
        ("peak torque / limit", _torque_cell(s["torque_peak_fraction"])),
        ("verification", "passed" if s["verification_passed"] else "FAILED"),
        ("solve time", f"{s['timings_s']['total']:.2f} s"),
    ]


def _torque_cell(fractions: dict[str, float] | None) -> str:
    """The joint nearest its torque limit and how near, or that the robot publishes no limits."""
    if not fractions:
        return "not checked (no published limits)"
    joint = max(fractions, key=lambda j: fractions[j])
    return f"{fractions[joint]:.0%} ({joint})"


def _cmd_acquire(args: argparse.Namespace) -> int:
    from rich.console import Console
    from rich.markup import escape

    from optlight.acquisition import ROUNDS, RoundFolders, acquire
    from optlight.export import check_output_folder
    from optlight.preflight import preflight

    out = Path(args.out)
    in_rounds = args.camera == "folder"  # a real camera: one run per round, continued in --out
    check_output_folder(out, overwrite=args.force, option="--out", force=FORCE, resume=ROUNDS if in_rounds else None)
    problem = load_problem(args.problem)
    rounds = RoundFolders(out, problem) if in_rounds else None  # the rounds' images checked before any work
    console = Console()  # stdout: stderr carries only the one-line error of a failed run
    with console.status("building the scene, objectives, robot and environment"):
        setup = preflight(problem)  # built once: the loop's first plan uses it as it is
    with console.status("") as status:

        def progress(iteration: int, stage: str, done: int, total: int) -> None:
            interrupts.check()  # a Ctrl-C that IPOPT turned into "User_Requested_Stop"
            status.update(f"iteration {iteration}: {stage} {done}/{total}")

        with warnings.catch_warnings(record=True):
            acquisition = acquire(setup, rounds or args.camera, progress=progress)
    interrupts.check()
    for it in acquisition.iterations:
        measure = "" if it.measure is None else f", {acquisition.measure} {it.measure:.4g}"
        console.print(
            f"iteration {it.index}: measured cost {it.measured_cost:.4g}, modelled {it.modelled_cost:.4g}"
            f"{measure}, {it.wall_time_s:.1f} s"
        )
    calibration = acquisition.calibration
    if calibration is not None:
        console.print(
            f"calibrated model: {calibration.light_model} light, power {calibration.power:.3g}, ambient "
            f"{calibration.ambient:.3g}, camera response γ {calibration.gamma:.3g} (calibration.json)"
        )
        if calibration.lamp is not None:
            console.print(escape(calibration.lamp.summary()))
    if acquisition.iterations:
        best = acquisition.best
        console.print(  # escaped: a failed re-plan's status names problem-file sections, not rich markup
            f"{escape(acquisition.status)}; best by the {acquisition.measure}: iteration {best.index}, "
            f"{best.score:.4g} ({best.score / max(acquisition.open_loop.score, 1e-300):.2f} × the open loop's)"
        )
    with console.status(f"writing {out}/"):
        acquisition.save(out, overwrite=args.force)
    if in_rounds:  # plain text, not wrapped: the user's instructions, with the command to paste
        command = shlex.join(["optlight", "acquire", args.problem, "--camera", "folder", "--out", args.out])
        print(acquisition.instructions(out, command))
    else:
        console.print(f"dataset: {out}/  (acquisition.json, captures.csv, lights.lp, measured_cost.png)")
    return 0


def _cmd_reach(args: argparse.Namespace) -> int:
    from optlight.export import check_output_folder, write_folder
    from optlight.planning.policy import Reacher
    from optlight.planning.reach import reachability_map
    from optlight.preflight import preflight

    check_output_folder(args.out, overwrite=args.force, option="--out", force=FORCE)
    problem = load_problem(args.problem)
    _check_reach_grid(problem, args.zenith_step, args.azimuth_step)
    setup = preflight(problem)
    reacher = Reacher(setup.workcell, setup.solver, setup.image_costs)
    result = reachability_map(reacher, zenith_step_deg=args.zenith_step, azimuth_step_deg=args.azimuth_step)
    interrupts.check()
    png, js = write_folder(
        args.out, lambda folder: result.save(folder), overwrite=args.force, option="--out", force=FORCE
    )
    print(f"{100 * result.reachable_fraction:.1f}% of the light cap reachable by {problem.robot.name}")
    if result.environment:
        print(f"{100 * result.taken_fraction:.1f}% of it taken by the environment (collision or view)")
    print(f"wrote {png} and {js}")
    return 0


def _check_reach_grid(problem: Problem, zenith_step: float, azimuth_step: float) -> None:
    """Refuse a reachability grid of more than :data:`MAX_REACH_CELLS` cells (as
    :func:`optlight.planning.reach.reachability_map` lays it over the cap), naming the smallest zenith
    step that fits with this azimuth step."""
    span = problem.light_sphere.zenith_max_deg - problem.light_sphere.zenith_min_deg
    n_z = math.ceil(span / zenith_step - 1e-9) + 1
    n_a = math.ceil(360.0 / azimuth_step - 1e-9)
    if n_z * n_a <= MAX_REACH_CELLS:
        return
    rows = MAX_REACH_CELLS // n_a
    fits = f"--zenith-step ≥ {span / (rows - 1):.3g} with this azimuth step" if rows >= 2 else "a larger --azimuth-step"
    raise UsageError(
        "--zenith-step",
        f"a grid of at most {MAX_REACH_CELLS} cells (an IK solve each): {n_z} zenith × {n_a} azimuth cells "
        f"over the cap's {span:g}° = {n_z * n_a}; give {fits}",
    )


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


def _cmd_simulate(args: argparse.Namespace) -> int:
    import json

    from optlight.export import check_output_file, write_file
    from optlight.simulation import simulate_folder

    if args.out is not None:
        check_output_file(args.out, overwrite=args.force, option="--out", force=FORCE)  # before any work
    report = simulate_folder(args.results)
    interrupts.check()
    for line in report.lines():
        print(line)
    if args.out is not None:
        text = json.dumps(report.to_dict(), indent=2, allow_nan=False) + "\n"
        out = write_file(args.out, lambda path: path.write_text(text), overwrite=args.force, option="--out", force=FORCE)
        print(f"wrote {out}")
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
    p.add_argument(
        "--camera",
        choices=("model", "mitsuba", "folder"),
        default="model",
        help="what captures: the model or Mitsuba camera, or a real one (folder: one run per round, see --out)",
    )
    p.add_argument(
        "--out",
        required=True,
        help="dataset folder, new or empty; with --camera folder also where each round's images go, and "
        "the same command continues an acquisition there",
    )
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
    p.add_argument("--force", action="store_true", help="replace a PNG that optlight rendered there")
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
    p = add(
        "simulate",
        _cmd_simulate,
        "run a results folder's joint trajectory in MuJoCo (optlight[sim]): tracking, light at the triggers, torques",
    )
    p.add_argument("results", metavar="RESULTS_DIR", help="a results folder of optlight solve")
    p.add_argument("--out", help="also write the numbers to this JSON file (not an existing one unless --force)")
    p.add_argument("--force", action="store_true", help="replace an existing JSON file")
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
        type=integer(1, max_local_workers(), f"worker processes ({WORKERS_PER_CORE} per usable core here)"),
        metavar="N",
        help=f"local cluster worker processes (default: one per core; at most {WORKERS_PER_CORE} per core)",
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
        with locks.holding():  # the outputs the command checks stay locked until it ends
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
