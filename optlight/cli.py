"""The ``optlight`` command.

Every subcommand takes PROBLEM as a path or the name of a file in ``problems/``. User mistakes
(an invalid problem file, an unreachable landmark, a plan that fails verification) are printed in
one line on stderr with exit status 2; no traceback.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable, Sequence

import numpy as np

from optlight.errors import OptlightError
from optlight.spec import available_problems, load_problem


def _cmd_check(args: argparse.Namespace) -> int:
    problem = load_problem(args.problem)
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


def _cmd_problems(args: argparse.Namespace) -> int:
    problems = available_problems()
    width = max((len(n) for n in problems), default=0)
    for name, description in problems.items():
        print(f"{name:<{width}}  {description}")
    return 0


def _cmd_bench(args: argparse.Namespace) -> int:
    import importlib.util
    from pathlib import Path

    runner = Path(__file__).resolve().parent.parent / "benchmarks" / "run.py"
    spec = importlib.util.spec_from_file_location("optlight_benchmarks.run", runner)
    if not runner.is_file() or spec is None or spec.loader is None:
        raise OptlightError(
            f"no benchmark runner at {runner}: `optlight bench` needs the source checkout "
            "(pip install -e . from the repository), or run `python benchmarks/run.py` there"
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
    p = add("render", _cmd_render, "render the camera image for one light position")
    p.add_argument("problem", help="problem file path or built-in name")
    p.add_argument("--zenith", type=float, required=True, help="light zenith, degrees from the camera axis")
    p.add_argument("--azimuth", type=float, required=True, help="light azimuth, degrees (90 = from above)")
    p.add_argument("--out", required=True, help="output PNG file")
    add("problems", _cmd_problems, "list the built-in problems")
    p = add("bench", _cmd_bench, "run the benchmarks, print the table, write benchmarks/results/latest.*")
    p.add_argument("names", nargs="*", metavar="PROBLEM", help="problem or component benchmark; default: all")
    p.add_argument("--quick", action="store_true", help="reduced sizes and one solve per problem (CI)")
    p.add_argument("--out", metavar="DIR", help="output folder (default benchmarks/results)")
    return parser


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
