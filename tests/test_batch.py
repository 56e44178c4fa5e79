"""Batch runs (optlight.batch): the spec, a run on a 2-worker local Dask cluster against the same
batch run serially here, failures and warnings per row, resuming, the scheduler's errors, and no
process left behind."""

from __future__ import annotations

import json
import logging
import os
import urllib.error
import urllib.request
from pathlib import Path

import numpy as np
import psutil
import pytest
from conftest import reduced_problem

import optlight
from optlight import engine
from optlight.batch import BatchSpec, batch_spec_from_dict, load_batch_spec, run_batch
from optlight.batch import run as batch_run
from optlight.cell import problem_toml
from optlight.cli import main
from optlight.engine import dask_client
from optlight.errors import ProblemError
from optlight.export import MANIFEST

#: Base placements of the test batch: two ordinary ones, one where the placement moves a landmark
#: (a UserWarning), one 5 m away where the panda reaches nothing (a failed row).
PLACEMENTS = [[0.0, 0.0, 0.0], [0.15, 0.0, 0.0], [0.0, -0.25, 0.0], [5.0, 0.0, 0.0]]
#: A reference light out of the camera's view, so that the ordinary rows have no warning at all.
REFERENCE = {"reference": {"kind": "light", "zenith_deg": 30.0, "azimuth_deg": 0.0}}
WARNS, FAILS = 2, 3


def write_spec(folder: Path, placements: list[list[float]] = PLACEMENTS) -> Path:
    """A base problem file (48² camera, 3 landmarks) and a batch spec over base placements."""
    folder.mkdir(parents=True, exist_ok=True)
    base = reduced_problem(camera_px=48, landmarks={"count": 3, "allow_partial": True}, objective=REFERENCE)
    (folder / "small.toml").write_text(problem_toml(base))
    spec = folder / "batch.toml"
    spec.write_text(
        'description = "test batch"\nproblem = "small.toml"\n\n[grid]\n'
        f'"robot.base_position_m" = {json.dumps(placements)}\n'
    )
    return spec


def _children() -> dict[int, str]:
    """This process's descendants, pid -> command line."""
    out = {}
    for p in psutil.Process().children(recursive=True):
        try:
            out[p.pid] = " ".join(p.cmdline())
        except psutil.Error:  # ended while we looked
            continue
    return out


@pytest.fixture(scope="module")
def cluster_run(tmp_path_factory: pytest.TempPathFactory) -> dict:
    """The test batch through the command line on a local cluster of 2 workers, with the processes
    of this test before, during (seen by a worker's task) and after it."""
    folder = tmp_path_factory.mktemp("batch")
    spec = write_spec(folder)
    before = _children()
    code = main(["batch", str(spec), "--out", str(folder / "cluster"), "--workers", "2"])
    return {"spec": spec, "out": folder / "cluster", "code": code, "before": before, "after": _children()}


@pytest.fixture(scope="module")
def serial_run(cluster_run: dict) -> optlight.BatchResult:
    """The same batch, one row after the other in this process."""
    return run_batch(cluster_run["spec"], cluster_run["out"].parent / "serial", serial=True, progress=False)


def _records(out: Path) -> dict[str, dict]:
    return {p.stem: json.loads(p.read_text()) for p in (out / "records").glob("*.json")}


def test_spec_rows_are_the_grid_times_the_listed_rows(tmp_path: Path) -> None:
    write_spec(tmp_path)
    data = {
        "problem": "small.toml",
        "grid": {"robot": {"base_position_m": [[0.0, 0.0, 0.0], [0.1, 0.0, 0.0]]}},
        "rows": [{"label": "three", "landmarks.count": 3}, {"landmarks": {"count": 5}}],
    }
    spec = batch_spec_from_dict(data, source=tmp_path / "inline.toml")
    assert len(spec.rows) == 4
    assert spec.keys == ("landmarks.count", "robot.base_position_m")
    got = [(r.problem.landmarks.count, r.problem.robot.base_position_m) for r in spec.rows]
    assert got == [(3, (0.0, 0.0, 0.0)), (3, (0.1, 0.0, 0.0)), (5, (0.0, 0.0, 0.0)), (5, (0.1, 0.0, 0.0))]
    assert spec.rows[0].id.startswith("three-") and len({r.id for r in spec.rows}) == 4
    # everything else is the base problem's
    base = spec.base.to_dict()
    row = spec.rows[3].problem.to_dict()
    row["landmarks"]["count"], row["robot"]["base_position_m"] = 3, [0.0, 0.0, 0.0]
    assert row == base


def test_a_row_id_changes_with_its_problem(tmp_path: Path) -> None:
    write_spec(tmp_path)
    one = batch_spec_from_dict(
        {"problem": "small.toml", "rows": [{"landmarks.count": 3}]}, tmp_path / "a.toml"
    )
    same = batch_spec_from_dict(
        {"problem": "small.toml", "rows": [{"landmarks.count": 3}]}, tmp_path / "b.toml"
    )
    other = batch_spec_from_dict(
        {"problem": "small.toml", "rows": [{"landmarks.count": 4}]}, tmp_path / "a.toml"
    )
    assert one.rows[0].id == same.rows[0].id != other.rows[0].id


@pytest.mark.parametrize(
    ("text", "key"),
    [
        ('problem = "small.toml"\nworkers = 3\n', "workers"),
        ('problem = "nowhere.toml"\n', "problem"),
        ('problem = "small.toml"\n[grid]\n"landmarks.count" = 3\n', "grid.landmarks.count"),
        ('problem = "small.toml"\n[grid]\n"landmarks.count" = [3, "four"]\n', "grid.landmarks.count[1]"),
        ('problem = "small.toml"\n[grid]\n"robot.nme" = ["x"]\n', "grid.robot.nme[0]"),
        (
            'problem = "small.toml"\n[grid]\n"robot.base_position_m" = [[0.0, 0.0]]\n',
            "grid.robot.base_position_m[0]",
        ),
        (
            'problem = "small.toml"\n[[rows]]\n"light_sphere.radius_m" = -1.0\n',
            "rows[0].light_sphere.radius_m",
        ),
        ('problem = "small.toml"\n[[rows]]\nlabel = 7\n', "rows[0].label"),
        ('problem = "small.toml"\n[[rows]]\n"camera.width" = 48\n[[rows]]\n"camera.width" = 48\n', "rows[1]"),
        ('problem = "small.toml"\npreview = "yes"\n', "preview"),
        ('problem = "small.toml"\n[grid\n', ""),
    ],
)
def test_a_malformed_spec_is_one_line_naming_the_file_and_key(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], text: str, key: str
) -> None:
    write_spec(tmp_path)
    bad = tmp_path / "bad.toml"
    bad.write_text(text)
    with pytest.raises(ProblemError) as caught:
        load_batch_spec(bad)
    assert caught.value.file == str(bad.resolve())
    assert caught.value.key.startswith(key)
    out = tmp_path / "out"
    assert main(["batch", str(bad), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and str(bad.resolve()) in err and key in err
    assert not out.exists()  # checked before any work


def test_the_output_folder_is_new_empty_or_an_earlier_batch(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A folder holding files optlight did not write, or another command's output, is refused in one
    line before the spec is read; so is a --workers that is not a positive integer."""
    spec = write_spec(tmp_path / "spec")
    foreign = tmp_path / "foreign"
    foreign.mkdir()
    (foreign / "thesis.tex").write_text("mine")
    (foreign / MANIFEST).write_text('{"files": ["thesis.tex"]}')  # even an optlight output of another kind
    assert main(["batch", str(spec), "--out", str(foreign)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--out" in err and "holds no earlier batch" in err
    assert sorted(p.name for p in foreign.iterdir()) == sorted([MANIFEST, "thesis.tex"])
    for workers in ("0", "-2", "two"):
        assert main(["batch", str(spec), "--out", str(tmp_path / "new"), "--workers", workers]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and "--workers" in err and workers in err
    assert not (tmp_path / "new").exists()


def test_an_unreachable_scheduler_is_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    spec = write_spec(tmp_path)
    monkeypatch.setattr(engine, "CONNECT_TIMEOUT_S", 1.0)
    before = _children()
    code = main(["batch", str(spec), "--out", str(tmp_path / "out"), "--scheduler", "tcp://127.0.0.1:1"])
    err = capsys.readouterr().err
    assert code == 2
    assert err.count("\n") == 1 and "cannot reach the Dask scheduler at 'tcp://127.0.0.1:1'" in err
    assert set(_children()) <= set(before)


@pytest.mark.slow
def test_the_cluster_run_finishes_every_row_and_records_the_failure(cluster_run: dict) -> None:
    assert cluster_run["code"] == 1  # a row failed
    spec: BatchSpec = load_batch_spec(cluster_run["spec"])
    records = _records(cluster_run["out"])
    assert set(records) == {row.id for row in spec.rows}
    failed = records[spec.rows[FAILS].id]
    assert failed["status"] == "failed" and failed["folder"] is None
    assert "no landmark is reachable by panda" in failed["error"]
    for i, row in enumerate(spec.rows):
        if i != FAILS:
            record = records[row.id]
            assert record["status"] == "ok", record["error"]
            assert (cluster_run["out"] / record["folder"] / "plan.json").is_file()
            assert record["metrics"]["verified"] is True
    assert any("moved from zenith" in w for w in records[spec.rows[WARNS].id]["warnings"])
    # an ordinary row places every landmark where it was found (its arm, kept out of the light's beam,
    # may leave the sphere between two captures: a warning of the path, not of the landmarks)
    assert not [w for w in records[spec.rows[0].id]["warnings"] if "moved" in w or "dropped" in w]
    table = (cluster_run["out"] / "results.csv").read_text().splitlines()
    assert len(table) == 1 + len(spec.rows) and table[0].startswith("row,robot.base_position_m,status")
    assert "no landmark is reachable" in (cluster_run["out"] / "results.md").read_text()


def test_no_process_is_left_behind(cluster_run: dict) -> None:
    """Every process the run started has ended; Python's one multiprocessing resource tracker (started
    for the first spawned process, ended with this process) is the only new child allowed."""
    new = {pid: cmd for pid, cmd in cluster_run["after"].items() if pid not in cluster_run["before"]}
    assert all("multiprocessing.resource_tracker" in cmd for cmd in new.values()), new


@pytest.mark.slow
def test_the_cluster_gives_the_serial_results(cluster_run: dict, serial_run: optlight.BatchResult) -> None:
    """The same records, trajectories and landmarks; to 1e-8 rather than bit for bit, since a Dask
    worker runs its BLAS single-threaded (another summation order) where this process may not."""
    cluster = _records(cluster_run["out"])
    assert serial_run.workers == 0 and len(serial_run.records) == len(cluster)
    for record in serial_run.records:
        other = cluster[record.id]
        assert (record.status, record.error, list(record.warnings)) == (
            other["status"],
            other["error"],
            other["warnings"],
        )
        for key, value in record.metrics.items():
            assert other["metrics"][key] == pytest.approx(value, rel=1e-8, abs=1e-10), key
        if record.folder is None:
            continue
        ours = np.loadtxt(serial_run.out / record.folder / "trajectory.csv", delimiter=",", skiprows=1)
        theirs = np.loadtxt(
            cluster_run["out"] / other["folder"] / "trajectory.csv", delimiter=",", skiprows=1
        )
        np.testing.assert_allclose(ours, theirs, rtol=1e-8, atol=1e-10)
        lights = [
            json.loads((out / f / "plan.json").read_text())["landmarks"]
            for out, f in ((serial_run.out, record.folder), (cluster_run["out"], other["folder"]))
        ]
        assert [lm["zenith_deg"] for lm in lights[0]] == pytest.approx([lm["zenith_deg"] for lm in lights[1]])


@pytest.mark.slow
def test_a_resumed_batch_solves_only_what_is_not_done(
    serial_run: optlight.BatchResult, monkeypatch: pytest.MonkeyPatch
) -> None:
    out = serial_run.out
    done = [r for r in serial_run.records if r.status == "ok"]
    stamps = {r.id: (out / r.folder / "plan.json").stat().st_mtime_ns for r in done if r.folder}
    (out / done[0].folder / "plan.json").unlink()  # an incomplete folder is not done
    (out / done[0].folder / "notes.md").write_text("mine")  # and a file the user put there stays
    solved: list[tuple[float, ...]] = []
    real = batch_run.solve_row

    def counted(problem: optlight.Problem, preview: bool = False, folder: str | None = None) -> dict:
        solved.append(problem.robot.base_position_m)
        return real(problem, preview, folder)

    monkeypatch.setattr(batch_run, "solve_row", counted)
    spec = load_batch_spec(out.parent / "batch.toml")
    again = run_batch(spec, out, serial=True, progress=False)
    assert sorted(solved) == sorted(
        [tuple(PLACEMENTS[FAILS]), tuple(done[0].overrides["robot.base_position_m"])]
    )
    skipped = {r.id for r in again.records if r.skipped}
    assert skipped == {r.id for r in done[1:]}
    for r in done[1:]:
        assert (out / r.folder / "plan.json").stat().st_mtime_ns == stamps[r.id]  # not written again
    assert (out / done[0].folder / "plan.json").is_file()
    assert (out / done[0].folder / "notes.md").read_text() == "mine"
    assert again.ok == serial_run.ok and again.failed == 1


def test_a_finished_batch_starts_no_cluster(cluster_run: dict, monkeypatch: pytest.MonkeyPatch) -> None:
    """Resuming a batch whose rows are all done (the failed row taken out of the spec) runs nothing."""
    spec = load_batch_spec(cluster_run["spec"])
    finished = BatchSpec(spec.source, spec.description, spec.base, spec.rows[:FAILS], spec.keys, spec.preview)

    def refuse(*args: object, **kwargs: object) -> None:
        raise AssertionError("a cluster was started")

    monkeypatch.setattr(engine, "dask_client", refuse)
    again = run_batch(finished, cluster_run["out"], progress=False)
    assert again.skipped == again.ok == FAILS


def test_the_local_cluster_listens_on_loopback_without_dashboard(monkeypatch: pytest.MonkeyPatch) -> None:
    """Every socket the cluster's processes listen on is on 127.0.0.1, and the scheduler's HTTP
    endpoint serves no dashboard (its /status page is not found; /health answers). The thread
    settings Dask's nannies put into this process's environment for their workers are undone on
    exit (they would keep later solves here single-threaded)."""
    monkeypatch.delenv("OMP_NUM_THREADS", raising=False)
    monkeypatch.setenv("MKL_NUM_THREADS", "3")
    with dask_client(workers=1) as client:
        assert os.environ.get("OMP_NUM_THREADS") == "1"  # what the workers were started with
        info = client.scheduler_info(n_workers=-1)
        processes = {psutil.Process().pid, *_children()}
        listening = [
            c.laddr
            for c in psutil.net_connections(kind="inet")
            if c.pid in processes and c.status == "LISTEN"
        ]
        assert len(listening) >= 3 and all(address.ip == "127.0.0.1" for address in listening), listening
        http = f"http://127.0.0.1:{info['services']['dashboard']}"
        assert urllib.request.urlopen(f"{http}/health", timeout=10).status == 200
        with pytest.raises(urllib.error.HTTPError) as missing:
            urllib.request.urlopen(f"{http}/status", timeout=10)
        assert missing.value.code == 404
    assert "OMP_NUM_THREADS" not in os.environ and os.environ["MKL_NUM_THREADS"] == "3"


def _log_in_worker(level: int, text: str) -> None:
    logging.getLogger("distributed.worker").log(level, text)


@pytest.mark.slow
def test_a_local_clusters_error_logs_do_not_reach_the_terminal(capfd: pytest.CaptureFixture[str]) -> None:
    """An ERROR a local cluster's worker logs (as Dask does when a heartbeat meets the scheduler
    already closed, with its traceback, at the end of a batch) is not printed on the terminal the
    workers share with this process: a row's failure is reported in the results, not in Dask's log."""
    with dask_client(workers=1) as client:
        client.run(_log_in_worker, logging.ERROR, "a worker's error at shutdown")
    assert "a worker's error at shutdown" not in capfd.readouterr().err


@pytest.mark.slow
def test_a_remote_scheduler_gets_the_rows_and_sends_the_plans_back(tmp_path: Path) -> None:
    """A scheduler given by address (a local cluster standing in for a remote one): its workers do
    not write into the output folder; the plans' files come back and are written here, the same
    files as a serial run's."""
    spec = write_spec(tmp_path, PLACEMENTS[:1])
    serial = run_batch(spec, tmp_path / "serial", serial=True, progress=False)
    before = _children()
    with dask_client(workers=1) as cluster:
        remote = run_batch(spec, tmp_path / "remote", scheduler=cluster.scheduler.address, progress=False)
        assert remote.workers == 1
    assert set(_children()) <= set(before) | {
        pid for pid, cmd in _children().items() if "multiprocessing.resource_tracker" in cmd
    }
    (ours,), (theirs,) = serial.records, remote.records
    assert theirs.status == "ok" and theirs.folder == ours.folder
    names = sorted(p.name for p in (serial.out / ours.folder).iterdir())
    assert names == sorted(p.name for p in (remote.out / theirs.folder).iterdir())
    assert "plan.json" in names
    for name in ("trajectory.csv", "lights.lp", "captures.csv"):
        assert (remote.out / theirs.folder / name).read_bytes() == (
            serial.out / ours.folder / name
        ).read_bytes()


@pytest.mark.slow
def test_the_example_batch_plans_every_row(tmp_path: Path) -> None:
    """The README's example batch, as shipped (here one row after the other): every row is planned
    and verified. Its third base placement was once (-0.05, -0.1, 0) m, where the view cone left
    landmark 150° blocked at both counts, so the example ended with two failed rows and exit 1."""
    path = Path(__file__).resolve().parents[1] / "examples" / "batch_placements.toml"
    spec = load_batch_spec(path)
    assert len(spec.rows) == 6 and spec.keys == ("robot.base_position_m", "landmarks.count")
    result = run_batch(path, tmp_path / "batch", serial=True, progress=False)
    assert (result.ok, result.failed) == (6, 0), [r.error for r in result.records if r.status != "ok"]
