"""The structure the code keeps: one public API list, imports that follow the layers without cycles,
a problem built once per solve, and a package that works installed outside the repository."""

from __future__ import annotations

import ast
import importlib
import os
import subprocess
import sys
from collections import Counter
from pathlib import Path

import pytest
from conftest import reduced_problem

import optlight

ROOT = Path(__file__).resolve().parent.parent
PACKAGE = ROOT / "optlight"

#: The layers, lowest first: a module may import from its own layer's package and from lower layers.
#: Where the light goes (objectives, landmarks) and how the robot gets there (policy, path,
#: trajectory NLP, timing) both live in planning, above the built setup and below verification; they
#: take the work cell (optlight.workcell), below the setup that builds it.
LAYERS: list[set[str]] = [
    {"errors", "jsondata", "interrupts", "cache", "threads"},
    {"locks"},
    {"spec"},
    {"geometry", "motion"},
    {"scene", "robot"},
    {"objectives", "environment", "photometric_stereo", "random_cells"},
    {"workcell"},
    {"setup"},
    {"capture"},
    {"planning"},
    {"verify"},
    {"stages"},
    {"export", "engine"},
    {"datasets"},
    {"viz"},
    {"report"},
    {"plan"},
    {"relocation"},
    {"pipeline", "preflight"},
    {"acquisition", "batch", "simulation"},
    {"cell"},
    {"cli"},
]


def _unit(module: str) -> str:
    """The layer unit of a dotted module name below optlight (its first component)."""
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else ""


def _layer(module: str) -> int:
    unit = _unit(module)
    return next(i for i, layer in enumerate(LAYERS) if unit in layer)


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _imports(path: Path) -> list[tuple[str, bool]]:
    """(imported optlight module, inside ``if TYPE_CHECKING``) of every import in ``path``, function-level
    ones included; ``from optlight.x import y`` counts as optlight.x.y when that is a module."""
    tree = ast.parse(path.read_text())
    type_only: set[int] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test):
            type_only |= {id(n) for stmt in node.body for n in ast.walk(stmt)}
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.module and node.module.startswith("optlight"):
            for alias in node.names:
                sub = f"{node.module}.{alias.name}"
                target = sub if _is_module(sub) else node.module
                found.append((target, id(node) in type_only))
        elif isinstance(node, ast.Import):
            found += [(a.name, id(node) in type_only) for a in node.names if a.name.startswith("optlight")]
    return found


def _is_module(name: str) -> bool:
    try:
        return importlib.util.find_spec(name) is not None
    except ModuleNotFoundError:  # the parent is a module, not a package
        return False


def _graph() -> dict[str, list[tuple[str, bool]]]:
    return {_module_name(p): _imports(p) for p in sorted(PACKAGE.rglob("*.py"))}


def test_every_module_has_a_layer() -> None:
    units = {_unit(m) for m in _graph() if m != "optlight"}
    assert units <= set().union(*LAYERS), units - set().union(*LAYERS)


def test_imports_follow_the_layers() -> None:
    wrong = [
        f"{module} imports {target}"
        for module, targets in _graph().items()
        if module != "optlight"
        for target, _ in targets
        if target != "optlight" and _layer(target) > _layer(module)
        or (_layer(target) == _layer(module) and _unit(target) != _unit(module))
    ]
    assert not wrong, wrong


def test_no_import_cycles() -> None:
    """No cycle among the imports that run (``TYPE_CHECKING`` ones are for the type checker only)."""
    graph = {m: {t for t, type_only in targets if not type_only} for m, targets in _graph().items()}
    state: dict[str, int] = {}
    cycles: list[list[str]] = []

    def visit(node: str, stack: list[str]) -> None:
        state[node] = 1
        for nxt in graph.get(node, ()):
            if state.get(nxt) == 1:
                cycles.append(stack[stack.index(nxt) :] + [nxt])
            elif nxt in graph and not state.get(nxt):
                visit(nxt, [*stack, nxt])
        state[node] = 2

    for module in graph:
        if not state.get(module):
            visit(module, [module])
    assert not cycles, cycles


#: What presents a plan (the results folder's report and its figures): the solve produces the plan
#: and hands each stage's result to its listener (optlight.stages); it draws and writes nothing.
PRESENTATION = ("optlight.report", "optlight.viz")


def test_the_solve_imports_no_presentation_module() -> None:
    """pipeline.py imports neither the report nor the figures (type-only imports included): the
    command line subscribes the figure worker to the solve's stages."""
    imported = [target for target, _ in _imports(PACKAGE / "pipeline.py")]
    assert not [t for t in imported if t.startswith(PRESENTATION)], imported


def test_planning_modules_take_what_they_use() -> None:
    """No planning module imports the setup module or its ``Setup`` (type-only imports included):
    the planners take the work cell, the image costs and their spec sections that ``Setup`` builds,
    never the whole setup nor, through it, the problem."""
    importing = sorted(
        module
        for module, targets in _graph().items()
        if module.startswith("optlight.planning") and any(t == "optlight.setup" for t, _ in targets)
    )
    assert not importing, importing
    naming = sorted(
        _module_name(path)
        for path in (PACKAGE / "planning").rglob("*.py")
        for node in ast.walk(ast.parse(path.read_text()))
        if isinstance(node, ast.ImportFrom)
        and (node.module or "").startswith("optlight")
        and any(alias.name == "Setup" for alias in node.names)
    )
    assert not naming, naming


#: Longest module in optlight/ (lines): one idea per module.
MAX_MODULE_LINES = 600


def test_every_module_holds_one_idea() -> None:
    long = {
        str(path.relative_to(ROOT)): n
        for path in PACKAGE.rglob("*.py")
        if (n := len(path.read_text(encoding="utf-8").splitlines())) > MAX_MODULE_LINES
    }
    assert not long, f"modules over {MAX_MODULE_LINES} lines: {long}"


def test_no_module_imports_another_modules_private_names() -> None:
    private = [
        f"{_module_name(path)}: from {node.module} import {alias.name}"
        for path in PACKAGE.rglob("*.py")
        for node in ast.walk(ast.parse(path.read_text()))
        if isinstance(node, ast.ImportFrom) and (node.module or "").startswith("optlight")
        for alias in node.names
        if alias.name.startswith("_")
    ]
    assert not private, private


def test_the_trajectory_type_and_jerk_timing_are_below_toppra() -> None:
    """The Trajectory type (optlight.motion) and the segment path (planning/chord.py) import no
    timing law; the jerk-limited timing is a peer of the TOPPRA one, not built on it."""
    for path in (PACKAGE / "motion.py", PACKAGE / "planning" / "chord.py", PACKAGE / "planning" / "jerk.py"):
        imported = [target for target, _ in _imports(path)]
        assert "optlight.planning.timing" not in imported and "optlight.planning.jerk" not in imported, path


def test_the_trajectory_type_does_not_import_toppra() -> None:
    """verify, export and the figures need the Trajectory type, not the TOPPRA timing (a fresh
    interpreter: this one has imported toppra already)."""
    code = "import sys, optlight.verify, optlight.export, optlight.viz.figures; print('toppra' in sys.modules)"
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert done.stdout.strip() == "False"


def test_the_solving_process_does_not_import_matplotlib_figure() -> None:
    """The command builds figure jobs and a worker draws them: its own process imports the figure
    modules, the plan and the reachability map, but not matplotlib.figure (~0.3 s; fresh interpreter)."""
    modules = "optlight.cli, optlight.plan, optlight.pipeline, optlight.planning.reach, optlight.cell"
    code = f"import sys, {modules}; print('matplotlib.figure' in sys.modules)"
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert done.stdout.strip() == "False"


def test_public_api_is_one_list() -> None:
    """``__all__`` holds every public name once; the lazy names are the ``TYPE_CHECKING`` imports of
    ``optlight/__init__.py``, and every name resolves to what its module defines."""
    assert len(optlight.__all__) == len(set(optlight.__all__))
    source = (PACKAGE / "__init__.py").read_text()
    declared = {name for name, _ in _type_checking_names(source)}
    assert declared == set(optlight._LAZY)
    for name, module in _type_checking_names(source):
        assert optlight._LAZY[name] == module
    for name in optlight.__all__:
        assert getattr(optlight, name) is not None


def _type_checking_names(source: str) -> list[tuple[str, str]]:
    tree = ast.parse(source)
    block = next(n for n in tree.body if isinstance(n, ast.If) and "TYPE_CHECKING" in ast.unparse(n.test))
    return [(a.name, s.module or "") for s in block.body if isinstance(s, ast.ImportFrom) for a in s.names]


@pytest.mark.parametrize("path", ["library", "cli"])
def test_a_solve_builds_each_object_once(path: str, monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    """One solve with the environment on builds the object mesh, the robot, each objective (camera and
    search resolution), the environment and its CasADi clearance and view functions once: through
    ``optlight.solve`` and through ``optlight solve``, whose preflight builds the Setup the solve uses.
    The clearance graph once per row selection: every row (the placement NLPs), the rows that can
    bind along the path (the trajectory NLP) and, where the start's straight line to the captures is
    not clear, those of the transfer NLP."""
    from optlight import environment, objectives, scene, setup
    from optlight.scene import objects

    counts: Counter[str] = Counter()

    def count(owner: object, name: str, label: str) -> None:
        real = getattr(owner, name)

        def counted(*args: object, **kwargs: object) -> object:
            counts[label] += 1
            return real(*args, **kwargs)

        monkeypatch.setattr(owner, name, counted)

    count(scene, "build_object", "object")
    count(objects, "build_object", "object")
    count(setup, "load_robot", "robot")
    count(setup.Scene, "resampled", "search scene")
    count(objectives.Objective, "from_problem", "objective")
    count(environment.Environment, "from_problem", "environment")
    selections: list[tuple[int, ...] | None] = []
    real_clearance = environment.Environment._build_clearance

    def recorded(self: environment.Environment, robot: object, rows: object) -> object:
        selections.append(None if rows is None else tuple(rows))  # type: ignore[call-overload]
        return real_clearance(self, robot, rows)  # type: ignore[arg-type]

    monkeypatch.setattr(environment.Environment, "_build_clearance", recorded)
    count(environment.Environment, "_build_view", "view graph")
    count(environment, "CollisionModel", "collision model")
    problem = reduced_problem("collision", camera_px=64, landmarks={"count": 4, "resolution": 32})
    if path == "library":
        optlight.solve(problem)
    else:
        from optlight import cli

        monkeypatch.setattr(cli, "load_problem", lambda name: problem)
        assert cli.main(["solve", "collision", "--out", str(tmp_path / "out")]) == 0
    assert counts == {
        "object": 1,
        "robot": 1,
        "search scene": 1,
        "objective": 2,
        "environment": 1,
        "view graph": 1,
        "collision model": 1,
    }, counts
    assert None in selections and len(selections) >= 2 and len(set(selections)) == len(selections), selections


@pytest.mark.slow
def test_installed_package_solves_from_another_folder(tmp_path: Path) -> None:
    """``pip install`` of the repository (not editable) into a folder of its own, then the CLI from an
    unrelated working folder: the built-in problems ship inside the package."""
    target = tmp_path / "site"
    subprocess.run(
        [sys.executable, "-m", "pip", "install", "--quiet", "--no-deps", "--target", str(target), str(ROOT)],
        check=True,
        cwd=tmp_path,
    )
    env = {**os.environ, "PYTHONPATH": str(target)}
    work = tmp_path / "elsewhere"
    work.mkdir()
    where = subprocess.run(
        [sys.executable, "-c", "import optlight.spec as s; print(s.__file__); print(s.PROBLEMS_DIR)"],
        capture_output=True, text=True, check=True, cwd=work, env=env,
    ).stdout.split()
    assert all(Path(p).is_relative_to(target) for p in where), where
    problems = subprocess.run(
        [sys.executable, "-m", "optlight.cli", "problems"], capture_output=True, text=True, cwd=work, env=env
    )
    assert problems.returncode == 0 and "default" in problems.stdout and "table_wall" in problems.stdout
    check = subprocess.run(
        [sys.executable, "-m", "optlight.cli", "check", "reference_image"],
        capture_output=True, text=True, cwd=work, env=env,
    )
    assert check.returncode == 0, check.stderr
    bench = subprocess.run(
        [sys.executable, "-m", "optlight.cli", "bench", "--quick"],
        capture_output=True,
        text=True,
        cwd=work,
        env=env,
    )
    assert bench.returncode == 2 and bench.stderr.count("\n") == 1 and "source repository" in bench.stderr
