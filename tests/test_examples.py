"""The examples run headless, as a user runs them (a subprocess from the repository root), exit 0
and write the files they announce. Reduced sizes (``--landmarks``) keep the whole module short."""

from __future__ import annotations

import csv
import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ROOT / "examples"


def run_example(name: str, out: Path, *args: str) -> str:
    """Run ``examples/<name>.py --out out [args]`` headless (stdin closed) and return its stdout."""
    done = subprocess.run(
        [sys.executable, str(EXAMPLES / f"{name}.py"), "--out", str(out), *args],
        cwd=ROOT,
        stdin=subprocess.DEVNULL,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert done.returncode == 0, f"{name} exited {done.returncode}\n{done.stdout}\n{done.stderr}"
    return done.stdout


@pytest.fixture(scope="module")
def quickstart(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A results folder written by the quickstart (6 landmarks); read_trajectory reads it too."""
    out = tmp_path_factory.mktemp("quickstart")
    stdout = run_example("quickstart", out, "--landmarks", "6")
    assert "verification passed" in stdout
    return out


def test_every_example_is_tested() -> None:
    tested = {"quickstart", "reference_image", "custom_mesh", "ik_only", "read_trajectory"}
    assert {p.stem for p in EXAMPLES.glob("*.py")} == tested


@pytest.mark.slow
def test_quickstart_writes_the_results_folder(quickstart: Path) -> None:
    names = {p.name for p in quickstart.iterdir()}
    assert {"trajectory.csv", "plan.json", "lights.lp", "preview.html", "report.md"} <= names
    assert len(json.loads((quickstart / "plan.json").read_text())["landmarks"]) == 6


@pytest.mark.slow
def test_reference_image_recovers_the_light(tmp_path: Path) -> None:
    stdout = run_example("reference_image", tmp_path, "--landmarks", "1")
    assert (tmp_path / "reference.png").is_file() and (tmp_path / "best.png").is_file()
    error = float(stdout.split("recovers the reference light within ")[1].split("°")[0])
    assert error < 2.0


def test_custom_mesh_writes_mesh_problem_and_renders(tmp_path: Path) -> None:
    stdout = run_example("custom_mesh", tmp_path, "--landmarks", "4")
    assert (tmp_path / "relief.ply").is_file() and (tmp_path / "problem.toml").is_file()
    assert len(list(tmp_path.glob("render_*.png"))) == 5
    assert "4 landmarks" in stdout


def test_ik_only_solves_every_target(tmp_path: Path) -> None:
    # the targets cover the whole cap (zenith 0–60°), which the panda reaches in the paper's layout
    default = (ROOT / "problems" / "default.toml").read_text()
    paper = tmp_path / "paper_layout.toml"
    paper.write_text(
        default.replace("center_m = [0.5, 0.0, 0.4]", "center_m = [0.35, 0.0, 0.45]").replace(
            "position_m = [-0.151, 0.376, 0.674]", "position_m = [-0.343, -0.4, 0.45]"
        )
    )
    assert paper.read_text() != default
    run_example("ik_only", tmp_path, "--problem", str(paper))
    with (tmp_path / "ik.csv").open() as f:
        rows = list(csv.DictReader(f))
    assert rows and all(row["success"] == "True" for row in rows)
    assert max(float(row["position_error_m"]) for row in rows) < 1e-4


def test_read_trajectory_finds_the_landmarks_at_the_captures(quickstart: Path, tmp_path: Path) -> None:
    stdout = run_example("read_trajectory", tmp_path, "--results", str(quickstart), "--rate", "25")
    assert (tmp_path / "trajectory_25hz.csv").is_file()
    deviation = float(stdout.split("max deviation ")[1].split(" m")[0])
    assert deviation < 1e-6


@pytest.mark.slow
def test_read_trajectory_solves_when_given_no_results(tmp_path: Path) -> None:
    run_example("read_trajectory", tmp_path, "--landmarks", "3")
    assert (tmp_path / "plan" / "plan.json").is_file() and (tmp_path / "trajectory_50hz.csv").is_file()
