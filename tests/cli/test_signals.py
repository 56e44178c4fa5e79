"""Stop signals through the command line: SIGTERM, SIGHUP and Ctrl-C (SIGINT) at named stages.

Each run is a real ``optlight solve`` or ``optlight batch`` subprocess that sends itself a signal the
first time it reaches a named stage (the test hook :data:`optlight.interrupts.TEST_SIGNAL_AT`), so
every moment is chosen, not a random wall time. Whatever the stage, the run must exit with 128 + the
signal's number and exactly one line on stderr (``optlight: terminated``, no traceback and no
"leaked semaphore" warning of multiprocessing's resource tracker, which would print on the same
stream), leave no process behind (every process it started carries a mark in its environment) and no
staging folder, and leave the user's files and an earlier output (updated with ``--force``)
byte-identical, or, for a signal that arrived once the output was in place, that output whole.

The runs of a group are started two at a time by a module fixture; the tests then check one run
each. Last, the figure worker ends with its parent when the parent is killed (SIGKILL).
"""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import time
import uuid
from collections.abc import Iterator
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import psutil
import pytest
from conftest import snapshot

from optlight import interrupts
from optlight.export import MANIFEST, STAGING_PREFIX

#: A problem whose whole solve and export take a few seconds: the default one, a 48² camera and 3
#: landmarks (the search may find fewer).
TINY = "[camera]\nwidth = 48\nheight = 48\n\n[landmarks]\ncount = 3\nallow_partial = true\n"
#: A batch of one row (the tiny problem), solved on a local cluster of one worker.
BATCH = 'problem = "tiny.toml"\n\n[[rows]]\nlabel = "near"\n"robot.base_position_m" = [0.0, 0.0, 0.0]\n'
#: A cell search over two base placements of the tiny problem, three given lights, the best solved.
CELL = 'problem = "tiny.toml"\nlights = [[40.0, 0.0], [40.0, 120.0], [40.0, 240.0]]\nsteps = 2\ntop = 1\n[search]\nbase_x_m = [-0.1, 0.1]\n'
#: Stages after which the output is in place: the signal leaves it whole.
WRITTEN = {"renames", "figure-worker-closing", "table-written", "done"}

#: (stage, signal, update an earlier output with --force) of ``optlight solve``, in the order the
#: run meets them: every progress stage of the pipeline, the figure worker, the export.
SOLVE_CASES = [
    ("imports", "SIGTERM", False),  # within the imports, where signals are deferred
    ("imports", "SIGHUP", True),
    ("figure-worker", "SIGTERM", True),  # the worker started and warming up
    ("figure-worker", "SIGINT", False),
    ("setup", "SIGTERM", False),
    ("landmarks", "SIGTERM", True),
    ("placement", "SIGINT", True),
    ("path", "SIGHUP", False),
    ("nlp", "SIGTERM", False),
    ("verify", "SIGTERM", True),
    ("staging-created", "SIGTERM", False),
    ("figures", "SIGTERM", True),  # waiting for the worker's figures, the staging folder half full
    ("staging-written", "SIGTERM", True),  # all written, before the final renames
    ("renames", "SIGTERM", True),  # deferred until the output is in place
    ("figure-worker-closing", "SIGTERM", False),  # held until the worker is shut down
]
#: (stage, signal) of ``optlight batch`` on a local cluster, in the order the run meets them.
BATCH_CASES = [
    ("imports", "SIGTERM"),
    ("imports", "SIGHUP"),
    ("spec-checked", "SIGTERM"),
    ("spec-checked", "SIGINT"),
    ("cluster-started", "SIGTERM"),  # the cluster up, no client yet
    ("client-connected", "SIGTERM"),
    ("tasks-submitted", "SIGTERM"),  # the worker busy with the row
    ("row-done", "SIGTERM"),
    ("rows-done", "SIGTERM"),
    ("cluster-closed", "SIGTERM"),
    ("table-written", "SIGTERM"),
    ("done", "SIGTERM"),
]
#: (stage, signal) of ``optlight cell`` on a local cluster.
CELL_CASES = [("client-connected", "SIGTERM"), ("tasks-submitted", "SIGHUP")]


@dataclass
class Outcome:
    """A finished run: its exit status, stderr, the processes it started still alive, and its folder
    (the command's working directory) before and after."""

    code: int
    err: str
    left: list[str]
    before: dict[str, str]
    after: dict[str, str]
    folder: Path



def marked(mark: str) -> list[str]:
    """The live processes whose environment holds ``OPTLIGHT_TEST_MARK=mark`` (the command's and
    every process it started, which inherit it), as ``pid command line``."""
    found = []
    for process in psutil.process_iter():
        try:
            if (
                process.environ().get("OPTLIGHT_TEST_MARK") == mark
                and process.status() != psutil.STATUS_ZOMBIE
            ):
                found.append(f"{process.pid} {' '.join(process.cmdline())[:120]}")
        except psutil.Error:  # gone, a zombie, or another user's
            continue
    return found


def run(args: list[str], folder: Path, at: str | None) -> Outcome:
    """``optlight ARGS`` in ``folder``, signalled at ``at`` ("stage:SIGNAME") when given. Returns once
    its stdout and stderr are closed: by it and by every process that inherited them."""
    mark = uuid.uuid4().hex
    env = {**os.environ, "OPTLIGHT_TEST_MARK": mark, "COLUMNS": "120"}
    env.pop(interrupts.TEST_SIGNAL_AT, None)
    if at is not None:
        env[interrupts.TEST_SIGNAL_AT] = at
    before = snapshot(folder)
    done = subprocess.run(
        [sys.executable, "-m", "optlight.cli", *args],
        cwd=folder,
        env=env,
        capture_output=True,
        text=True,
        timeout=600,  # a hang fails the test rather than stalling the suite
    )
    return Outcome(done.returncode, done.stderr, marked(mark), before, snapshot(folder), folder)


def complete(folder: Path) -> bool:
    """A whole output folder: its manifest lists files that all exist."""
    try:
        files = json.loads((folder / MANIFEST).read_text())["files"]
    except (OSError, ValueError, KeyError):
        return False
    return bool(files) and all((folder / f).is_file() for f in files)


def case_id(case: tuple) -> str:
    return "-".join(str(c) for c in case).replace("True", "force").replace("-False", "")


def run_all(jobs: dict[tuple, tuple[list[str], Path, str | None]]) -> dict[tuple, Outcome]:
    """The runs of ``jobs`` (key -> arguments of :func:`run`), two at a time."""
    with ThreadPoolExecutor(max_workers=2) as pool:
        futures = {key: pool.submit(run, *job) for key, job in jobs.items()}
        return {key: future.result() for key, future in futures.items()}


@pytest.fixture(scope="module", autouse=True)
def signals_not_ignored() -> Iterator[None]:
    """The stop signals handled in this process, so in the commands it starts too: started in the
    background of a non-interactive shell it ignores SIGINT, under ``nohup`` SIGHUP, and the
    commands would rightly go on ignoring them (an ignored disposition survives exec)."""
    ignored = [s for s in interrupts.SIGNALS if signal.getsignal(s) is signal.SIG_IGN]
    for signum in ignored:
        signal.signal(signum, signal.default_int_handler if signum == signal.SIGINT else signal.SIG_DFL)
    yield
    for signum in ignored:
        signal.signal(signum, signal.SIG_IGN)


@pytest.fixture(scope="module")
def root(tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("signals")
    (folder / "tiny.toml").write_text(f'description = "tiny"\n\n{TINY}')
    (folder / "batch.toml").write_text(BATCH)
    (folder / "cell.toml").write_text(CELL)
    return folder


@pytest.fixture(scope="module")
def solve_runs(root: Path) -> dict[tuple, Outcome]:
    """Every case of :data:`SOLVE_CASES`, each in a folder of its own holding a user's file beside
    the output and, for the ``--force`` cases, an earlier output (with a file the user added)."""
    reference = root / "reference"
    reference.mkdir()
    first = run(["solve", "../tiny.toml", "--out", "out"], reference, None)
    assert first.code == 0 and first.err == "" and complete(reference / "out"), first.err
    jobs = {}
    for i, case in enumerate(SOLVE_CASES):
        stage, signame, force = case
        folder = root / f"solve{i}"
        folder.mkdir()
        (folder / "mine.txt").write_text("the user's notes\n")
        if force:
            shutil.copytree(reference / "out", folder / "out")
            (folder / "out" / "user.md").write_text("added by the user\n")
        args = ["solve", "../tiny.toml", "--out", "out", *(["--force"] if force else [])]
        jobs[case] = (args, folder, f"{stage}:{signame}")
    return run_all(jobs)


@pytest.fixture(scope="module")
def batch_runs(root: Path) -> dict[tuple, Outcome]:
    """Every case of :data:`BATCH_CASES` on a local cluster of one worker, each in a folder of its
    own holding a user's file and an earlier solve's output beside the batch's."""
    jobs = {}
    for i, case in enumerate(BATCH_CASES):
        stage, signame = case
        folder = root / f"batch{i}"
        folder.mkdir()
        (folder / "mine.txt").write_text("the user's notes\n")
        (folder / "earlier").mkdir()
        (folder / "earlier" / "plan.json").write_text('{"an": "earlier output"}\n')
        args = ["batch", "../batch.toml", "--out", "out", "--workers", "1"]
        jobs[case] = (args, folder, f"{stage}:{signame}")
    return run_all(jobs)


@pytest.fixture(scope="module")
def cell_runs(root: Path) -> dict[tuple, Outcome]:
    """Every case of :data:`CELL_CASES` on a local cluster of one worker, each in a folder of its own
    holding a user's file."""
    jobs = {}
    for i, case in enumerate(CELL_CASES):
        folder = root / f"cell{i}"
        folder.mkdir()
        (folder / "mine.txt").write_text("the user's notes\n")
        jobs[case] = (["cell", "../cell.toml", "--out", "out", "--workers", "1"], folder, ":".join(case))
    return run_all(jobs)


def assert_stopped(outcome: Outcome, signame: str) -> None:
    """Exit 128 + the signal's number, exactly the one line, no process and no staging folder left."""
    signum = signal.Signals[signame]
    assert outcome.code == 128 + signum, (outcome.code, outcome.err)
    assert outcome.err == f"optlight: {interrupts.SIGNALS[signum]}\n"
    assert outcome.left == []
    assert [p for p in outcome.after if STAGING_PREFIX in p] == []


def test_enough_moments_are_signalled() -> None:
    """SIGTERM at 10 moments of a solve and of a batch at least, SIGINT and SIGHUP at a few."""
    for cases in (SOLVE_CASES, BATCH_CASES):
        assert len({c[0] for c in cases if c[1] == "SIGTERM"}) >= 10
        assert {"SIGINT", "SIGHUP"} <= {c[1] for c in cases}


@pytest.mark.parametrize("case", SOLVE_CASES, ids=[case_id(c) for c in SOLVE_CASES])
def test_a_signalled_solve_stops_cleanly_and_keeps_the_files(
    case: tuple[str, str, bool], solve_runs: dict[tuple, Outcome]
) -> None:
    stage, signame, force = case
    outcome = solve_runs[case]
    assert_stopped(outcome, signame)
    if stage not in WRITTEN:  # every file as it was: the user's, and an earlier output
        assert outcome.after == outcome.before
        return
    # the output is in place, whole; the user's files are unchanged
    assert complete(outcome.folder / "out")
    outside = {p: h for p, h in outcome.before.items() if not p.startswith("out/") or p == "out/user.md"}
    assert {p: outcome.after.get(p) for p in outside} == outside


@pytest.mark.parametrize("case", BATCH_CASES, ids=[case_id(c) for c in BATCH_CASES])
def test_a_signalled_batch_stops_cleanly_and_keeps_the_files(
    case: tuple[str, str], batch_runs: dict[tuple, Outcome]
) -> None:
    stage, signame = case
    outcome = batch_runs[case]
    assert_stopped(outcome, signame)
    # the batch's own folder keeps what was done (a run into it resumes); nothing else changed
    outside = {p: h for p, h in outcome.before.items() if p != "out" and not p.startswith("out/")}
    assert {p: h for p, h in outcome.after.items() if p != "out" and not p.startswith("out/")} == outside
    if stage in WRITTEN:
        assert (outcome.folder / "out" / "results.csv").is_file()


@pytest.mark.parametrize("case", CELL_CASES, ids=[case_id(c) for c in CELL_CASES])
def test_a_signalled_cell_search_stops_cleanly_and_keeps_the_files(
    case: tuple[str, str], cell_runs: dict[tuple, Outcome]
) -> None:
    outcome = cell_runs[case]
    assert_stopped(outcome, case[1])
    assert outcome.after == outcome.before  # no output folder: it is written at the end, whole


def test_signals_are_latched_deferred_and_named() -> None:
    """In-process: SIGTERM and SIGHUP raise an Interrupt that names them and stay pending after a
    library swallowed them; within deferred() they wait for the block's end; the exit statuses."""
    with interrupts.latched():
        for signum in (signal.SIGTERM, signal.SIGHUP):
            with pytest.raises(interrupts.Interrupt) as raised:
                os.kill(os.getpid(), signum)
                time.sleep(5.0)  # cut short: the handler raises as soon as it runs
            assert raised.value.signum == signum and isinstance(raised.value, KeyboardInterrupt)
        assert interrupts.received() == signal.SIGTERM  # the first one is kept
        with pytest.raises(interrupts.Interrupt):
            interrupts.check()
        done = []
        with interrupts.held():  # a cleanup runs although a signal is pending
            done.append("cleaned up")
        assert done
    assert not interrupts.pending() and interrupts.received() == signal.SIGINT

    with interrupts.latched():
        done = []
        with pytest.raises(interrupts.Interrupt) as raised, interrupts.deferred():
            os.kill(os.getpid(), signal.SIGHUP)
            time.sleep(0.2)  # the handler runs here, and only records the signal
            done.append("the block ran to its end")
        assert done and raised.value.signum == signal.SIGHUP
    assert [interrupts.exit_status(s) for s in interrupts.SIGNALS] == [130, 143, 129]

    previous = signal.signal(signal.SIGHUP, signal.SIG_IGN)  # as under nohup: it stays ignored
    try:
        with interrupts.latched():
            os.kill(os.getpid(), signal.SIGHUP)
            time.sleep(0.2)
            assert not interrupts.pending()
        assert signal.getsignal(signal.SIGHUP) is signal.SIG_IGN
    finally:
        signal.signal(signal.SIGHUP, previous)


FIGURE_WORKER_CHILD = """
import sys
from matplotlib.figure import Figure
from optlight.viz.drawing import FigureJob, FigureWorker

if __name__ == "__main__":
    worker = FigureWorker()
    worker.draw(FigureJob.of(Figure(figsize=(1, 1)), 20)).result()  # the worker is up
    print("ready", flush=True)
    sys.stdin.read()  # until killed
"""


def test_the_figure_worker_ends_when_its_parent_is_killed(tmp_path: Path) -> None:
    """SIGKILL of a process with a figure worker: the worker (and multiprocessing's resource
    tracker) end too, so the caller's pipes close and nothing is left."""
    script = tmp_path / "parent.py"
    script.write_text(FIGURE_WORKER_CHILD)
    parent = subprocess.Popen(
        [sys.executable, str(script)],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    assert parent.stdout is not None and parent.stdout.readline() == "ready\n"
    children = psutil.Process(parent.pid).children(recursive=True)
    assert any("spawn_main" in " ".join(c.cmdline()) for c in children)
    parent.kill()
    parent.communicate(timeout=120)  # returns once the worker and the tracker closed the pipes
    gone, alive = psutil.wait_procs(children, timeout=120)
    assert alive == []


@pytest.mark.parametrize(
    ("command", "at"),
    [
        (["check", "tiny.toml"], "imports:SIGTERM"),
        (["render", "tiny.toml", "--zenith", "10", "--azimuth", "0", "--out", "a.png"], "imports:SIGHUP"),
        (
            ["reach", "tiny.toml", "--out", "reach", "--zenith-step", "90", "--azimuth-step", "360"],
            "staging-written:SIGTERM",
        ),
        (
            ["reach", "tiny.toml", "--out", "reach", "--zenith-step", "90", "--azimuth-step", "360"],
            "staging-created:SIGHUP",
        ),
        (["check", "tiny.toml"], "done:SIGTERM"),
    ],
    ids=["check-imports", "render-imports", "reach-staging-written", "reach-staging-created", "check-done"],
)
def test_every_command_stops_the_same_way_in_process(
    command: list[str], at: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capfd: pytest.CaptureFixture
) -> None:
    """The other commands, run in-process (:func:`optlight.cli.main`): the same status and line, and
    the folder as it was."""
    from optlight.cli import main

    (tmp_path / "tiny.toml").write_text(f'description = "tiny"\n\n{TINY}')
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv(interrupts.TEST_SIGNAL_AT, at)
    before = snapshot(tmp_path)
    capfd.readouterr()
    signum = signal.Signals[at.split(":")[1]]
    assert main(command) == 128 + signum
    assert capfd.readouterr().err == f"optlight: {interrupts.SIGNALS[signum]}\n"
    assert snapshot(tmp_path) == before


def test_a_batch_removes_the_staging_folders_its_stopped_workers_left(tmp_path: Path) -> None:
    """A worker stopped as it saved a plan leaves its staging folder: beside the plan's folder (in
    plans/, or in the batch folder before plans/ existed) or in the plan's folder. Leaving the batch's
    engine removes them, and nothing else; with a remote cluster (whose workers go on) none."""
    from optlight.batch.run import no_staging_left

    kept = [tmp_path / "records" / "a.json", tmp_path / "plans" / "a" / "plan.json", tmp_path / "results.csv"]
    for path in kept:
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text("{}")
    staged = [tmp_path / "plans" / "a" / f"{STAGING_PREFIX}1", tmp_path / "plans" / f"{STAGING_PREFIX}2"]
    staged += [tmp_path / f"{STAGING_PREFIX}3"]
    for folder in staged:
        (folder / "figures").mkdir(parents=True)
        (folder / "figures" / "half.png").write_bytes(b"\x89PNG")
    with pytest.raises(interrupts.Interrupt), no_staging_left(tmp_path, local=False):
        raise interrupts.Interrupt(signal.SIGTERM)
    assert all(folder.is_dir() for folder in staged)
    with pytest.raises(interrupts.Interrupt), no_staging_left(tmp_path, local=True):
        raise interrupts.Interrupt(signal.SIGTERM)
    assert not any(folder.exists() for folder in staged) and all(path.is_file() for path in kept)
