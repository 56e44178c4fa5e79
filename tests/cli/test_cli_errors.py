"""Bad input through the command line: one line on stderr, no traceback, nothing destroyed.

Every case below is something a user can type or write. Each must give a non-zero exit status and
exactly one line on stderr (``optlight: error: …`` naming the file and key, or the option), leave
every file and folder that existed byte-identical and leave nothing behind (no staging folder, no
partial output). Most cases run in-process through :func:`optlight.cli.main` (``capfd`` captures
file descriptors 1 and 2, so C libraries' output counts too); a representative set runs as real
subprocesses. Then: property tests that mutate mesh files and ``--out`` targets, and the interrupt
latch in-process (signals sent to real commands at named stages: test_signals.py).
"""

from __future__ import annotations

import importlib
import json
import os
import random
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from conftest import snapshot
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from PIL import Image

from optlight.cli import main
from optlight.export import MANIFEST, STAGING_PREFIX
from optlight.robot.catalogue import example_robot_data_dir

#: The default problem shrunk so a whole solve (and its export) takes a few seconds.
SMALL = {"camera": {"width": 64, "height": 64}, "landmarks": {"count": 6}}
#: `optlight reach` over two cells: a fast command that writes an output folder.
FAST_REACH = ["--zenith-step", "90", "--azimuth-step", "360"]


# --------------------------------------------------------------------------------------------
# Files
# --------------------------------------------------------------------------------------------


def toml_text(data: dict, prefix: str = "") -> str:
    """A TOML document for the value types problem files use (tables, arrays of tables, scalars)."""

    def value(v: object) -> str:
        if isinstance(v, bool):
            return "true" if v else "false"
        if isinstance(v, str):
            return json.dumps(v)
        if isinstance(v, list):
            return "[" + ", ".join(value(x) for x in v) + "]"
        return repr(v)

    lines, tables = [], []
    for k, v in data.items():
        if isinstance(v, dict):
            tables.append(f"[{prefix}{k}]\n{toml_text(v, f'{prefix}{k}.')}")
        elif isinstance(v, list) and v and isinstance(v[0], dict):
            tables += [f"[[{prefix}{k}]]\n{toml_text(item, f'{prefix}{k}.')}" for item in v]
        else:
            lines.append(f"{k} = {value(v)}")
    return "\n".join(lines + tables) + "\n"


def merged(base: dict, extra: dict) -> dict:
    out = {k: dict(v) if isinstance(v, dict) else v for k, v in base.items()}
    for k, v in extra.items():
        out[k] = {**out.get(k, {}), **v} if isinstance(v, dict) else v
    return out


def problem(folder: Path, name: str, **sections: dict) -> str:
    """Write ``name``.toml: the small default problem with ``sections`` merged in; returns its path."""
    path = folder / f"{name}.toml"
    path.write_text(toml_text(merged({"description": name, **SMALL}, sections)))
    return str(path)


TRIANGLE_OBJ = "v 0 0 0\nv 0.05 0 0\nv 0 0.05 0\nf 1 2 3\n"
NO_LIMITS_URDF = (
    '<robot name="r"><link name="a"/><link name="b"/><joint name="j" type="revolute">'
    '<parent link="a"/><child link="b"/><axis xyz="0 0 1"/></joint></robot>'
)
ONE_JOINT_URDF = (
    '<robot name="r"><link name="a"/><link name="b">{visual}</link><joint name="j" type="revolute">'
    '<parent link="a"/><child link="b"/><axis xyz="0 0 1"/>'
    '<limit lower="-1" upper="1" effort="1" velocity="1"/></joint></robot>'
)
MISSING_MESH = '<visual><geometry><mesh filename="package://nowhere_pkg/meshes/x.stl"/></geometry></visual>'


def make_workspace(root: Path) -> None:
    """The user's folder: their own files, an earlier optlight output, and every bad input file."""
    (root / "existing.txt").write_text("my notes\n")
    (root / "foreign").mkdir()
    (root / "foreign" / "thesis.tex").write_text("\\documentclass{article}\n")
    (root / "empty").mkdir()
    (root / "folder.png").mkdir()
    (root / "existing.png").write_bytes(b"\x89PNG not really")
    old = root / "old_results"
    old.mkdir()
    (old / "plan.json").write_text("{}\n")
    (old / "notes.md").write_text("the user's, not optlight's\n")
    (old / MANIFEST).write_text(json.dumps({"files": ["plan.json"]}))
    (root / "broken_link").symlink_to(root / "no_such_target")

    meshes = root / "meshes"
    meshes.mkdir()
    rng = np.random.default_rng(16)
    (meshes / "garbage.obj").write_bytes(rng.integers(0, 256, 400, dtype=np.uint8).tobytes())
    (meshes / "garbage.stl").write_bytes(rng.integers(0, 256, 400, dtype=np.uint8).tobytes())
    (meshes / "garbage.ply").write_bytes(b"ply\nformat ascii 1.0\nelement vertex 3\n")
    (meshes / "garbage.glb").write_bytes(b"glTF" + bytes(40))
    (meshes / "empty.obj").write_bytes(b"")
    (meshes / "points.obj").write_text("v 0 0 0\nv 0.01 0 0\nv 0 0.01 0\n")
    (meshes / "nan.obj").write_text("v nan 0 0\nv 0.01 0 0\nv 0 0.01 0\nf 1 2 3\n")
    (meshes / "huge.obj").write_text("v -1 -1 0\nv 1 -1 0\nv 0 1 0\nf 1 2 3\n")  # larger than b = 0.4 m
    (meshes / "latin1.obj").write_bytes(("# café crème\n" + TRIANGLE_OBJ).encode("latin-1"))
    (meshes / "folder.obj").mkdir()

    urdfs = root / "urdfs"
    urdfs.mkdir()
    (urdfs / "garbage.urdf").write_text("<robot <<< not xml")
    (urdfs / "empty.urdf").write_text("")
    (urdfs / "no_limits.urdf").write_text(NO_LIMITS_URDF)
    (urdfs / "missing_mesh.urdf").write_text(ONE_JOINT_URDF.format(visual=MISSING_MESH))
    (urdfs / "ok.urdf").write_text(ONE_JOINT_URDF.format(visual=""))

    images = root / "images"
    images.mkdir()
    (images / "garbage.png").write_bytes(b"\x89PNG\r\n\x1a\n" + bytes(30))
    Image.fromarray(np.zeros((64, 64), np.uint8)).save(images / "black_mask.png")
    Image.fromarray(np.full((64, 64), 128, np.uint8)).save(images / "grey.png")


def write_bad_problems(root: Path) -> dict[str, str]:
    """Problem files with one mistake each, by name."""
    p = root / "problems"
    p.mkdir()
    m, u, i = root / "meshes", root / "urdfs", root / "images"

    def mesh(name: str) -> dict:
        return {"object": {"kind": "mesh", "path": str(m / name)}}

    def urdf(name: str, frame: str = "b") -> dict:
        return {"robot": {"name": "mine", "urdf": str(u / name), "frame": frame}}

    image_ref = {"reference": {"kind": "image", "image": str(i / "grey.png")}}
    files = {
        "small": problem(p, "small"),
        "mesh_garbage_obj": problem(p, "mesh_garbage_obj", **mesh("garbage.obj")),
        "mesh_garbage_stl": problem(p, "mesh_garbage_stl", **mesh("garbage.stl")),
        "mesh_garbage_ply": problem(p, "mesh_garbage_ply", **mesh("garbage.ply")),
        "mesh_garbage_glb": problem(p, "mesh_garbage_glb", **mesh("garbage.glb")),
        "mesh_empty": problem(p, "mesh_empty", **mesh("empty.obj")),
        "mesh_points": problem(p, "mesh_points", **mesh("points.obj")),
        "mesh_nan": problem(p, "mesh_nan", **mesh("nan.obj")),
        "mesh_folder": problem(p, "mesh_folder", **mesh("folder.obj")),
        "mesh_missing": problem(p, "mesh_missing", **mesh("nowhere.obj")),
        "mesh_huge": problem(p, "mesh_huge", **mesh("huge.obj")),
        "sphere_too_big": problem(p, "sphere_too_big", object={"kind": "sphere", "radius_m": 0.5}),
        "face_too_big": problem(p, "face_too_big", object={"face": {"height_m": 0.8}}),
        "camera_inside": problem(p, "camera_inside", camera={"position_m": [0.35, -0.2, 0.45]}),
        "camera_away": problem(p, "camera_away", camera={"look_at_m": [0.35, -2.0, 0.45]}),
        "urdf_garbage": problem(p, "urdf_garbage", **urdf("garbage.urdf")),
        "urdf_empty": problem(p, "urdf_empty", **urdf("empty.urdf")),
        "urdf_no_limits": problem(p, "urdf_no_limits", **urdf("no_limits.urdf")),
        "urdf_missing_mesh": problem(p, "urdf_missing_mesh", **urdf("missing_mesh.urdf")),
        "urdf_missing_frame": problem(p, "urdf_missing_frame", **urdf("ok.urdf", frame="tool")),
        "urdf_missing_file": problem(p, "urdf_missing_file", **urdf("nowhere.urdf")),
        "urdf_without_frame": problem(p, "urdf_without_frame", robot={"urdf": str(u / "ok.urdf")}),
        "frame_unknown": problem(p, "frame_unknown", robot={"frame": "nose"}),
        "robot_unknown": problem(p, "robot_unknown", robot={"name": "r2d2"}),
        "ref_missing": problem(
            p, "ref_missing", objective={"reference": {"kind": "image", "image": "nowhere.png"}}
        ),
        "ref_garbage": problem(
            p, "ref_garbage", objective={"reference": {"kind": "image", "image": str(i / "garbage.png")}}
        ),
        "ref_mask_empty": problem(
            p,
            "ref_mask_empty",
            objective={"reference": {**image_ref["reference"], "mask": str(i / "black_mask.png")}},
        ),
        "ref_no_image": problem(p, "ref_no_image", objective={"reference": {"kind": "image"}}),
        "pattern_unknown_field": problem(
            p, "pattern_unknown_field", trajectory={"image_pattern": "img_{foo}.png"}
        ),
        "pattern_constant": problem(p, "pattern_constant", trajectory={"image_pattern": "img.png"}),
        "pattern_space": problem(p, "pattern_space", trajectory={"image_pattern": "img {index}.png"}),
        "pattern_bad_spec": problem(p, "pattern_bad_spec", trajectory={"image_pattern": "{index:q}.png"}),
        "pattern_positional": problem(p, "pattern_positional", trajectory={"image_pattern": "{0}.png"}),
        "memory": problem(p, "memory", camera={"width": 8192, "height": 8192}),
        "count_huge": problem(p, "count_huge", landmarks={"count": 100000}),
        "radius_negative": problem(p, "radius_negative", light_sphere={"radius_m": -0.5}),
        "zenith_range": problem(p, "zenith_range", light_sphere={"zenith_min_deg": 50, "zenith_max_deg": 40}),
        "max_iter_zero": problem(p, "max_iter_zero", solver={"max_iter": 0}),
        "noise_negative": problem(p, "noise_negative", light={"noise_std": -0.1}),
        "unknown_key": problem(p, "unknown_key", object={"colour": "red"}),
        "max_iter_one": problem(p, "max_iter_one", solver={"max_iter": 1}),
    }
    (p / "broken.toml").write_text("[object\nkind = ")
    files["broken"] = str(p / "broken.toml")
    return files



def staging_left(root: Path) -> list[str]:
    return [str(p) for p in root.rglob(f"{STAGING_PREFIX}*")]


@pytest.fixture(scope="module")
def workspace(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict[str, str]]:
    import optlight.pipeline  # noqa: F401 - imported once here, so no case's time includes the imports
    import optlight.preflight  # noqa: F401
    import optlight.report  # noqa: F401

    root = tmp_path_factory.mktemp("user")
    make_workspace(root)
    return root, write_bad_problems(root)


@pytest.fixture
def in_workspace(workspace: tuple[Path, dict[str, str]], monkeypatch: pytest.MonkeyPatch) -> Iterator[Path]:
    monkeypatch.chdir(workspace[0])
    yield workspace[0]


# --------------------------------------------------------------------------------------------
# The bad inputs
# --------------------------------------------------------------------------------------------

#: (id, command line, fragment the one error line must hold); {name} is the problem file of that name.
CASES: list[tuple[str, list[str], str]] = [
    # mesh files that cannot be used
    ("mesh garbage obj", ["check", "{mesh_garbage_obj}"], "object.path"),
    ("mesh garbage stl", ["check", "{mesh_garbage_stl}"], "object.path"),
    ("mesh garbage ply", ["check", "{mesh_garbage_ply}"], "object.path"),
    ("mesh garbage glb", ["check", "{mesh_garbage_glb}"], "object.path"),
    ("mesh empty", ["check", "{mesh_empty}"], "object.path"),
    ("mesh without triangles", ["check", "{mesh_points}"], "object.path"),
    ("mesh with nan", ["check", "{mesh_nan}"], "object.path"),
    ("mesh is a folder", ["check", "{mesh_folder}"], "object.path"),
    ("mesh missing", ["check", "{mesh_missing}"], "object.path"),
    ("mesh garbage at solve", ["solve", "{mesh_garbage_obj}", "--out", "new_a"], "object.path"),
    (
        "mesh garbage at render",
        ["render", "{mesh_garbage_stl}", "--zenith", "10", "--azimuth", "0", "--out", "n.png"],
        "object.path",
    ),
    # geometry
    ("mesh larger than the light sphere", ["check", "{mesh_huge}"], "light_sphere.radius_m"),
    ("sphere larger than the light sphere", ["check", "{sphere_too_big}"], "object.radius_m"),
    ("face larger than the light sphere", ["check", "{face_too_big}"], "light_sphere.radius_m"),
    ("camera inside the light sphere", ["check", "{camera_inside}"], "camera.position_m"),
    ("camera looking away", ["check", "{camera_away}"], "camera.look_at_m"),
    # robots
    ("urdf not xml", ["check", "{urdf_garbage}"], "robot.urdf"),
    ("urdf empty", ["check", "{urdf_empty}"], "robot.urdf"),
    ("urdf the parser rejects", ["check", "{urdf_no_limits}"], "robot.urdf"),
    ("urdf mesh does not resolve", ["check", "{urdf_missing_mesh}"], "package://nowhere_pkg"),
    ("urdf without the frame", ["check", "{urdf_missing_frame}"], "robot.frame"),
    ("urdf missing", ["check", "{urdf_missing_file}"], "robot.urdf"),
    ("urdf without frame key", ["check", "{urdf_without_frame}"], "robot.frame"),
    ("frame unknown", ["check", "{frame_unknown}"], "robot.frame"),
    ("frame unknown at reach", ["reach", "{frame_unknown}", "--out", "new_b", *FAST_REACH], "robot.frame"),
    ("robot unknown", ["check", "{robot_unknown}"], "robot.name"),
    # reference images
    ("reference image missing", ["check", "{ref_missing}"], "objective.reference.image"),
    ("reference image garbage", ["check", "{ref_garbage}"], "objective.reference.image"),
    ("reference mask covers nothing", ["check", "{ref_mask_empty}"], "objective.reference.mask"),
    ("reference image not given", ["check", "{ref_no_image}"], "objective.reference.image"),
    # image-name patterns
    ("pattern unknown field", ["check", "{pattern_unknown_field}"], "trajectory.image_pattern"),
    ("pattern without index", ["check", "{pattern_constant}"], "trajectory.image_pattern"),
    ("pattern with a space", ["check", "{pattern_space}"], "trajectory.image_pattern"),
    ("pattern bad format spec", ["check", "{pattern_bad_spec}"], "trajectory.image_pattern"),
    ("pattern positional field", ["check", "{pattern_positional}"], "trajectory.image_pattern"),
    ("pattern at solve", ["solve", "{pattern_unknown_field}", "--out", "new_c"], "trajectory.image_pattern"),
    # memory, ranges, messages
    ("camera too large for memory", ["check", "{memory}"], "camera.width"),
    ("integer echoed as written", ["check", "{count_huge}"], "got 100000"),
    ("negative radius", ["check", "{radius_negative}"], "got -0.5"),
    ("zenith range empty", ["check", "{zenith_range}"], "light_sphere.zenith_max_deg"),
    ("max_iter zero", ["check", "{max_iter_zero}"], "solver.max_iter"),
    ("negative noise", ["check", "{noise_negative}"], "light.noise_std"),
    ("unknown key", ["check", "{unknown_key}"], "object.colour"),
    ("invalid toml", ["check", "{broken}"], "valid TOML"),
    ("unknown problem", ["check", "no_such_problem"], "built-in problem"),
    (
        "max_iter one is a solver limit",
        ["solve", "{max_iter_one}", "--out", "new_d"],
        "[solver] max_iter",
    ),
    # command-line arguments
    ("zenith nan", ["render", "{small}", "--zenith", "nan", "--azimuth", "0", "--out", "n.png"], "--zenith"),
    ("zenith inf", ["render", "{small}", "--zenith", "inf", "--azimuth", "0", "--out", "n.png"], "--zenith"),
    (
        "zenith negative",
        ["render", "{small}", "--zenith", "-5", "--azimuth", "0", "--out", "n.png"],
        "--zenith",
    ),
    (
        "zenith above 180",
        ["render", "{small}", "--zenith", "200", "--azimuth", "0", "--out", "n.png"],
        "--zenith",
    ),
    (
        "azimuth text",
        ["render", "{small}", "--zenith", "10", "--azimuth", "abc", "--out", "n.png"],
        "--azimuth",
    ),
    (
        "azimuth overflow",
        ["render", "{small}", "--zenith", "10", "--azimuth", "1e400", "--out", "n.png"],
        "--azimuth",
    ),
    ("zenith step zero", ["reach", "{small}", "--zenith-step", "0", "--out", "new_e"], "--zenith-step"),
    ("zenith step negative", ["reach", "{small}", "--zenith-step", "-1", "--out", "new_e"], "--zenith-step"),
    ("zenith step nan", ["reach", "{small}", "--zenith-step", "nan", "--out", "new_e"], "--zenith-step"),
    (
        "azimuth step negative",
        ["reach", "{small}", "--azimuth-step", "-10", "--out", "new_e"],
        "--azimuth-step",
    ),
    ("azimuth step zero", ["reach", "{small}", "--azimuth-step", "0", "--out", "new_e"], "--azimuth-step"),
    (
        "azimuth step too large",
        ["reach", "{small}", "--azimuth-step", "1000", "--out", "new_e"],
        "--azimuth-step",
    ),
    ("render without out", ["render", "{small}", "--zenith", "10", "--azimuth", "0"], "--out"),
    ("unknown command", ["frobnicate"], "invalid choice"),
    ("solve without problem", ["solve"], "required"),
    ("unknown option", ["check", "{small}", "--frobnicate"], "unrecognized arguments"),
    # output locations
    ("solve into a file", ["solve", "{small}", "--out", "existing.txt"], "existing file"),
    (
        "solve into a file with force",
        ["solve", "{small}", "--out", "existing.txt", "--force"],
        "existing file",
    ),
    ("solve into a foreign folder", ["solve", "{small}", "--out", "foreign"], "did not write"),
    (
        "solve into a foreign folder with force",
        ["solve", "{small}", "--out", "foreign", "--force"],
        "did not write",
    ),
    ("solve into the non-empty working folder", ["solve", "{small}", "--out", "."], "did not write"),
    ("solve into an earlier output", ["solve", "{small}", "--out", "old_results"], "--force"),
    ("solve below a file", ["solve", "{small}", "--out", "existing.txt/sub"], "is a file"),
    (
        "solve where nothing can be written",
        ["solve", "{small}", "--out", "/proc/optlight-out"],
        "cannot write",
    ),
    ("solve into a broken link", ["solve", "{small}", "--out", "broken_link"], "broken symbolic link"),
    ("solve a built-in into a foreign folder", ["solve", "default", "--out", "foreign"], "did not write"),
    (
        "render over an existing png",
        ["render", "{small}", "--zenith", "10", "--azimuth", "0", "--out", "existing.png"],
        "--force",
    ),
    (
        "render into a folder",
        ["render", "{small}", "--zenith", "10", "--azimuth", "0", "--out", "folder.png", "--force"],
        "is a folder",
    ),
    (
        "render to a non-png name",
        ["render", "{small}", "--zenith", "10", "--azimuth", "0", "--out", "existing.txt"],
        ".png",
    ),
    (
        "render where nothing can be written",
        ["render", "{small}", "--zenith", "10", "--azimuth", "0", "--out", "/proc/x.png"],
        "cannot write",
    ),
    ("reach into a file", ["reach", "{small}", "--out", "existing.txt", *FAST_REACH], "existing file"),
    ("reach into a foreign folder", ["reach", "{small}", "--out", "foreign", *FAST_REACH], "did not write"),
    ("reach into an earlier output", ["reach", "{small}", "--out", "old_results", *FAST_REACH], "--force"),
]

#: Cases that also run as real subprocesses (the console script's own stderr, C libraries included).
SUBPROCESS_CASES = {
    "mesh garbage obj",
    "urdf the parser rejects",
    "urdf mesh does not resolve",
    "pattern unknown field",
    "camera too large for memory",
    "zenith nan",
    "zenith step zero",
    "azimuth step negative",
    "solve into a file",
    "solve into a foreign folder",
    "solve into the non-empty working folder",
    "render into a folder",
    "reach into a file",
}


def argv_of(case: list[str], files: dict[str, str]) -> list[str]:
    return [arg.format(**files) if arg.startswith("{") else arg for arg in case]


def assert_one_error_line(code: int, out: str, err: str, fragment: str) -> None:
    lines = [line for line in err.splitlines() if line.strip()]
    assert code == 2, (code, out, err)
    assert "Traceback" not in out + err
    assert len(lines) == 1, err
    assert lines[0].startswith("optlight: error: ") and fragment in lines[0], lines[0]
    assert "np.float64" not in lines[0]


def test_there_are_at_least_sixty_distinct_bad_inputs() -> None:
    assert len({name for name, _, _ in CASES}) == len(CASES) >= 60
    assert len({tuple(argv) for _, argv, _ in CASES}) == len(CASES)


@pytest.mark.parametrize(("name", "case", "fragment"), CASES, ids=[c[0] for c in CASES])
def test_bad_input_in_process(
    name: str,
    case: list[str],
    fragment: str,
    workspace: tuple[Path, dict[str, str]],
    in_workspace: Path,
    capfd,
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    root, files = workspace
    before = snapshot(root)
    if name != "max_iter one is a solver limit":  # the only case that runs the solver
        # refused in the check phase: the work each command starts after its checks never begins
        for module, function in LONG_WORK:
            monkeypatch.setattr(importlib.import_module(module), function, _must_not_start(function))
    code = main(argv_of(case, files))
    out, err = capfd.readouterr()
    assert_one_error_line(code, out, err, fragment)
    assert snapshot(root) == before, "a file or folder that existed changed, or something was left"
    assert not staging_left(root)


#: The long work of ``solve``, ``reach`` and ``acquire``, which the command imports when it starts it.
LONG_WORK = [
    ("optlight.pipeline", "solve"),
    ("optlight.planning.reach", "reachability_map"),
    ("optlight.acquisition", "acquire"),
]


def _must_not_start(function: str):
    def started(*args, **kwargs):
        raise AssertionError(f"{function} started: the input was not refused in the check phase")

    return started


@pytest.mark.parametrize(
    ("name", "case", "fragment"),
    [c for c in CASES if c[0] in SUBPROCESS_CASES],
    ids=[c[0] for c in CASES if c[0] in SUBPROCESS_CASES],
)
def test_bad_input_as_a_subprocess(
    name: str, case: list[str], fragment: str, workspace: tuple[Path, dict[str, str]]
) -> None:
    root, files = workspace
    before = snapshot(root)
    run = subprocess.run(
        [sys.executable, "-m", "optlight.cli", *argv_of(case, files)],
        cwd=root,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert_one_error_line(run.returncode, run.stdout, run.stderr, fragment)
    assert snapshot(root) == before
    assert not staging_left(root)


def test_subprocess_cases_are_cases() -> None:
    assert SUBPROCESS_CASES <= {name for name, _, _ in CASES}


def test_valid_inputs_the_issue_named_pass(
    workspace: tuple[Path, dict[str, str]], in_workspace: Path, capfd
) -> None:
    """A valid OBJ with a Latin-1 comment, a user URDF from example-robot-data whose meshes are four
    folders up, and `check` itself: valid, nothing on stderr."""
    root, _ = workspace
    kinova = example_robot_data_dir() / "example-robot-data/robots/kinova_description/robots/kinova.urdf"
    latin = problem(root, "latin1", object={"kind": "mesh", "path": str(root / "meshes" / "latin1.obj")})
    arm = problem(
        root, "user_kinova", robot={"name": "k", "urdf": str(kinova), "frame": "j2s6s200_end_effector"}
    )
    for path in (latin, arm):
        assert main(["check", path]) == 0
        out, err = capfd.readouterr()
        assert "valid" in out and err == ""


def test_outputs_land_whole_and_force_keeps_user_files(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capfd
) -> None:
    """reach into a new folder, refused a second time, replaced with --force: the user's file stays."""
    files = {"small": problem(tmp_path, "small")}
    monkeypatch.chdir(tmp_path)
    assert main(["reach", files["small"], "--out", "deep/new/out", *FAST_REACH]) == 0
    out_dir = tmp_path / "deep" / "new" / "out"
    manifest = json.loads((out_dir / MANIFEST).read_text())
    assert sorted(manifest["files"]) == ["reachability.json", "reachability.png"]
    (out_dir / "notes.md").write_text("mine")
    capfd.readouterr()
    assert main(["reach", files["small"], "--out", str(out_dir), *FAST_REACH]) == 2
    assert "--force" in capfd.readouterr().err
    assert main(["reach", files["small"], "--out", str(out_dir), "--force", *FAST_REACH]) == 0
    assert sorted(p.name for p in out_dir.iterdir()) == sorted([MANIFEST, "notes.md", *manifest["files"]])
    assert (out_dir / "notes.md").read_text() == "mine" and not staging_left(tmp_path)
    (tmp_path / "empty").mkdir()
    assert main(["render", files["small"], "--zenith", "10", "--azimuth", "0", "--out", "empty/a.png"]) == 0
    assert (tmp_path / "empty" / "a.png").read_bytes()[:4] == b"\x89PNG"


def test_solve_writes_every_figure_and_stops_its_figure_worker(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The command draws its figures in a worker process: all of them land, as PNGs, and the
    process is gone when the command returns."""
    import multiprocessing

    small = problem(tmp_path, "small")
    monkeypatch.chdir(tmp_path)
    before = set(multiprocessing.active_children())
    assert main(["solve", small, "--out", "out"]) == 0
    assert not set(multiprocessing.active_children()) - before
    pngs = sorted(p.name for p in (tmp_path / "out").glob("*.png"))
    stems = ["landmarks_cost", "landmarks_histograms", "landmarks_images", "landmarks_polar", "path", "trajectory"]
    assert pngs == [f"{stem}.png" for stem in stems]
    for name in pngs:
        with Image.open(tmp_path / "out" / name) as image:
            assert min(image.size) > 100 and len(image.getcolors(1 << 16) or range(257)) > 16  # drawn, not blank
    assert all(f"![{stem}]({stem}.png)" in (tmp_path / "out" / "report.md").read_text() for stem in stems)
    # the scene was built in the command's checks, not in the solve: no "scene" stage of 0 s is reported
    timings = json.loads((tmp_path / "out" / "plan.json").read_text())["summary"]["timings_s"]
    assert list(timings) == ["landmarks", "placement", "path", "nlp", "timing", "verify", "total"]
    assert "| scene |" not in (tmp_path / "out" / "report.md").read_text()


# --------------------------------------------------------------------------------------------
# Properties: mutated mesh files, any --out target
# --------------------------------------------------------------------------------------------

ENCODINGS = ["utf-8", "latin-1", "utf-16", "utf-32", "cp1252", "shift_jis", "utf-8-sig", "utf-16-be"]
TRIANGLE_STL = (
    "solid t\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 0.05 0 0\nvertex 0 0.05 0\n"
    "endloop\nendfacet\nendsolid t\n"
)
MESH_LINES = st.lists(
    st.sampled_from(["v 0 0 0", "v 0.05 0 0", "v 0 0.05 0", "f 1 2 3", "# é ü ß 日本", "vn 0 0 1", "f 1 2"])
    | st.text(max_size=20),
    max_size=12,
).map("\n".join)


@st.composite
def mesh_files(draw: st.DrawFn) -> tuple[bytes, str, bool]:
    """(content, suffix, valid): a valid triangle in any text encoding, or random lines, random bytes,
    an empty file, a valid file with bytes changed or cut off, under any mesh suffix."""
    kind = draw(st.sampled_from(["valid", "lines", "bytes", "empty", "mutated"]))
    encoding = draw(st.sampled_from(ENCODINGS))
    if kind == "valid":
        text, suffix = draw(
            st.sampled_from([("# café 日本\n" + TRIANGLE_OBJ, ".obj"), (TRIANGLE_STL, ".stl")])
        )
        return text.encode(encoding, errors="replace"), suffix, True
    suffix = draw(st.sampled_from([".obj", ".stl", ".ply", ".off", ".glb"]))
    if kind == "lines":
        return draw(MESH_LINES).encode(encoding, errors="replace"), suffix, False
    if kind == "bytes":
        return draw(st.binary(max_size=600)), suffix, False
    if kind == "empty":
        return b"", suffix, False
    data = bytearray(draw(st.sampled_from([TRIANGLE_OBJ, TRIANGLE_STL])).encode(encoding, errors="replace"))
    for _ in range(draw(st.integers(1, 6))):
        data[draw(st.integers(0, len(data) - 1))] = draw(st.integers(0, 255))
    return bytes(data[: draw(st.integers(0, len(data)))]), suffix, False


@settings(max_examples=60, deadline=None, derandomize=True, suppress_health_check=list(HealthCheck))
@given(file=mesh_files())
def test_any_mesh_file_is_valid_or_one_line(
    file: tuple[bytes, str, bool], workspace: tuple[Path, dict[str, str]], capfd
) -> None:
    """Whatever the bytes, `check` says valid or gives one line naming the key; a valid triangle
    passes in every encoding (trimesh needs charset-normalizer for those that are not UTF-8)."""
    content, suffix, valid = file
    root, _ = workspace
    folder = root / "fuzz"
    folder.mkdir(exist_ok=True)
    mesh = folder / f"m{suffix}"
    mesh.write_bytes(content)
    path = problem(folder, "fuzz", object={"kind": "mesh", "path": str(mesh)})
    capfd.readouterr()
    code = main(["check", path])
    out, err = capfd.readouterr()
    if valid:
        assert code == 0, err
    if code == 0:
        assert "valid" in out and err == ""
    else:
        keys = ("object.path", "light_sphere.radius_m", "camera")
        lines = err.splitlines()
        assert code == 2 and len(lines) == 1 and "Traceback" not in out + err, err
        assert any(k in lines[0] for k in keys), lines[0]


@st.composite
def out_targets(draw: st.DrawFn) -> tuple[str, bool, bool]:
    """A state of the --out location; returns (kind, force, expect refusal) after building it in "target"."""
    kind = draw(
        st.sampled_from(
            [
                "missing",
                "nested",
                "file",
                "empty",
                "foreign",
                "results",
                "results+user",
                "bad_manifest",
                "link",
            ]
        )
    )
    return kind, draw(st.booleans()), kind in ("file", "foreign", "bad_manifest", "link")


def build_target(base: Path, kind: str, rng: random.Random) -> Path:
    target = base / "target"
    if kind == "nested":
        return base / "a" / "b" / "target"
    if kind == "file":
        target.write_bytes(rng.randbytes(rng.randint(0, 50)))
    elif kind == "link":
        target.symlink_to(base / "nowhere")
    elif kind != "missing":
        target.mkdir()
    if kind in ("foreign", "results+user", "bad_manifest"):
        for i in range(rng.randint(1, 3)):
            (target / f"user_{i}.txt").write_bytes(rng.randbytes(rng.randint(0, 50)))
    if kind.startswith("results"):
        (target / "reachability.png").write_bytes(b"old")
        (target / "stale.json").write_bytes(b"old")  # an earlier run wrote it; this one does not
        (target / MANIFEST).write_text(json.dumps({"files": ["reachability.png", "stale.json"]}))
    if kind == "bad_manifest":
        (target / MANIFEST).write_text(json.dumps({"files": ["../outside"]}))
    return target


@settings(max_examples=20, deadline=None, derandomize=True, suppress_health_check=list(HealthCheck))
@given(spec=out_targets(), seed=st.integers(0, 2**16))
@pytest.mark.slow
def test_any_out_target_is_refused_whole_or_written_whole(
    spec: tuple[str, bool, bool], seed: int, tmp_path_factory: pytest.TempPathFactory, capfd
) -> None:
    kind, force, refused = spec
    base = tmp_path_factory.mktemp("out")
    target = build_target(base, kind, random.Random(seed))
    path = problem(base, "small")
    before = snapshot(base)
    capfd.readouterr()
    code = main(["reach", path, "--out", str(target), *(["--force"] if force else []), *FAST_REACH])
    out, err = capfd.readouterr()
    refused = refused or (kind.startswith("results") and not force)
    assert not staging_left(base)
    if refused:
        assert code == 2 and len(err.splitlines()) == 1 and "Traceback" not in err, err
        assert snapshot(base) == before
        return
    assert code == 0 and err == "", err
    after = snapshot(base)
    written = {"reachability.png", "reachability.json", MANIFEST}
    rel = str(target.relative_to(base))
    for entry, digest in before.items():  # whatever optlight did not write is untouched
        name = Path(entry).name
        if not entry.startswith(rel + "/") or name.startswith("user_"):
            assert after.get(entry) == digest, entry
    assert {Path(e).name for e in after if e.startswith(rel + "/")} == written | {
        Path(e).name for e in before if e.startswith(rel + "/user_")
    }
    assert sorted(json.loads((target / MANIFEST).read_text())["files"]) == sorted(written - {MANIFEST})


# --------------------------------------------------------------------------------------------
# Ctrl-C: the interrupt latch in-process (signals at named stages of real commands: test_signals.py)
# --------------------------------------------------------------------------------------------


def test_interrupts_latch_defer_and_stay_quiet() -> None:
    """A swallowed Ctrl-C is raised again by check(); within deferred() it waits for the block's end;
    one raised where Python cannot propagate it (a __del__) is not reported."""
    from optlight import interrupts

    # Python's own handler, whatever an earlier test (a cluster, a subprocess) left in force
    signal.signal(signal.SIGINT, signal.default_int_handler)
    with interrupts.latched():
        try:
            os.kill(os.getpid(), signal.SIGINT)
            time.sleep(1.0)  # the handler runs here
        except KeyboardInterrupt:
            pass  # swallowed, as CasADi's IPOPT interface does
        assert interrupts.pending()
        with pytest.raises(KeyboardInterrupt):
            interrupts.check()
    assert not interrupts.pending()

    done = []
    with pytest.raises(KeyboardInterrupt), interrupts.deferred():
        os.kill(os.getpid(), signal.SIGINT)
        time.sleep(1.0)  # the handler runs here (on a loaded machine it may take a while)
        done.append("the block ran to its end")
    assert done

    reported = []
    previous, sys.unraisablehook = sys.unraisablehook, reported.append
    try:

        class Dying:
            def __del__(self) -> None:
                raise KeyboardInterrupt

        with interrupts.latched():
            try:
                os.kill(os.getpid(), signal.SIGINT)
                time.sleep(1.0)
            except KeyboardInterrupt:
                pass
            Dying()  # its KeyboardInterrupt cannot propagate
        Dying()  # outside latched(): reported as usual
    finally:
        sys.unraisablehook = previous
    assert len(reported) == 1


def test_an_error_that_a_swallowed_ctrl_c_caused_is_the_interrupt(
    monkeypatch: pytest.MonkeyPatch, capfd
) -> None:
    """IPOPT swallows a Ctrl-C and returns "User_Requested_Stop"; the NLP then fails and the planner
    raises its SolverError before the next progress callback: the command still exits 130."""
    from optlight import cli
    from optlight.errors import SolverError

    def stopped(args: object) -> int:
        try:
            os.kill(os.getpid(), signal.SIGINT)
            time.sleep(1.0)  # the handler runs here
        except KeyboardInterrupt:
            pass  # swallowed, as CasADi's IPOPT interface does
        raise SolverError("the trajectory NLP failed (User_Requested_Stop after 3 iterations)")

    monkeypatch.setattr(cli, "_cmd_check", stopped)
    capfd.readouterr()
    assert main(["check", "default"]) == 130
    assert capfd.readouterr().err == "optlight: interrupted\n"
