"""Figures drawn in a worker process: the same PNG bytes as drawn here, errors sent back, the
process gone once the worker is closed; a plan's results folder the same with or without one."""

from __future__ import annotations

import math
import multiprocessing
from functools import partial
from pathlib import Path

import numpy as np
import pytest
from conftest import reduced_problem

import optlight
from optlight.planning.timing import time_parameterize
from optlight.report import FigureDrafts
from optlight.viz.drawing import FigureJob, FigureWorker
from optlight.viz.trajectory_figures import trajectory_figure

LIMITS = {"lower": -3.0, "upper": 3.0, "velocity_limit": 1.0, "acceleration_limit": 2.0}


def _trajectory_job() -> FigureJob:
    """A figure whose argument is a timed trajectory (what a results folder sends the worker)."""
    waypoints = np.array([[0.0, 0.0], [0.6, -0.4], [0.1, 0.5]])
    segments = [a + (b - a) * np.linspace(0.0, 1.0, 5)[:, None] for a, b in zip(waypoints[:-1], waypoints[1:], strict=True)]
    trajectory = time_parameterize(segments, np.ones(2), np.full(2, 2.0), 0.2)
    return FigureJob(partial(trajectory_figure, **LIMITS), (trajectory,), 60)


def test_a_worker_draws_what_this_process_draws_then_stops() -> None:
    job = _trajectory_job()
    before = set(multiprocessing.active_children())
    with FigureWorker() as worker:
        drawn = worker.draw(job).result(timeout=120)
        started = set(multiprocessing.active_children()) - before
        assert len(started) == 1  # the worker's own process
        with pytest.raises(ValueError, match="math domain error"):
            worker.draw(FigureJob(math.sqrt, (-1.0,), 60)).result(timeout=120)  # raised there, seen here
    assert drawn[:8] == b"\x89PNG\r\n\x1a\n" and drawn == job.png()
    assert not set(multiprocessing.active_children()) - before
    assert [process.exitcode for process in started] == [0]  # ended, not killed, by its shortcut exit


@pytest.mark.slow
def test_a_results_folder_is_the_same_with_a_worker(tmp_path: Path) -> None:
    """Drawn here, or by a worker: the landmark figures while the motion is planned, the motion's
    while it is verified (both as the solve's stages finish: FigureDrafts), and written by save. The
    same bytes either way, with a capture the placement moved (drawn where it is captured: solve and
    save give the figures the same captures)."""
    problem = reduced_problem(camera_px=64, landmarks={"count": 18})
    here, there = tmp_path / "here", tmp_path / "there"
    optlight.solve(problem).save(here, preview=False)
    with FigureWorker() as worker:
        drafts = FigureDrafts(worker)
        plan = optlight.solve(problem, on_stage=drafts)
        assert [c.index for c in plan.visited if c.status == "placed"] == [7]
        landmark_stems = ["landmarks_cost", "landmarks_histograms", "landmarks_images", "landmarks_polar"]
        # all drawn as the solve's stages finished
        assert sorted(drafts.figures) == sorted([*landmark_stems, "path", "trajectory"])
        plan.save(there, preview=False, worker=worker, drawn=drafts.figures)
    files = sorted(p.name for p in here.iterdir())
    assert files == sorted(p.name for p in there.iterdir())
    pngs = [name for name in files if name.endswith(".png")]
    assert pngs == sorted(f"{stem}.png" for stem in [*landmark_stems, "path", "trajectory"])
    for name in [*pngs, "trajectory.csv", "lights.lp"]:
        assert (here / name).read_bytes() == (there / name).read_bytes(), name
