"""Timing with TOPPRA: limits kept under dense resampling, dwells at rest, CSV round trip."""

from __future__ import annotations

import csv

import numpy as np
import pytest
import toppra.algorithm
from hypothesis import given, settings
from hypothesis import strategies as st

from optlight.errors import SolverError
from optlight.motion import Trajectory
from optlight.planning import timing
from optlight.planning.timing import time_parameterize

VMAX = np.array([1.0, 1.5, 0.8])
AMAX = np.array([3.0, 2.0, 4.0])


def _segments(landmarks: np.ndarray, k: int = 6, bump: float = 0.2) -> list[np.ndarray]:
    """Curved segments between consecutive landmarks: straight line plus a sine bump on joint 0."""
    s = np.linspace(0.0, 1.0, k)[:, None]
    out = []
    for a, b in zip(landmarks[:-1], landmarks[1:], strict=True):
        w = a + (b - a) * s
        w[:, 0] += bump * np.sin(np.pi * s[:, 0])
        out.append(w)
    return out


LANDMARKS = np.array([[0.0, 0.0, 0.0], [0.8, -0.5, 0.3], [0.2, 0.4, -0.6], [1.0, 0.1, 0.0]])


def _dense_ratios(
    traj: Trajectory, vmax: np.ndarray, amax: np.ndarray, rate_hz: float
) -> tuple[float, float]:
    q, qd, qdd = traj.sample(traj.sample_times(rate_hz))
    return float(np.max(np.abs(qd) / vmax)), float(np.max(np.abs(qdd) / amax))


def test_dwells_are_at_rest_at_the_landmarks() -> None:
    dwell = 0.3
    traj = time_parameterize(_segments(LANDMARKS), VMAX, AMAX, dwell)
    m = len(LANDMARKS)
    assert traj.landmark_intervals.shape == (m, 2)
    assert traj.segment_times.shape == (m - 1, 2)
    np.testing.assert_allclose(np.diff(traj.landmark_intervals, axis=1).ravel(), dwell)
    np.testing.assert_allclose(traj.capture_times, traj.landmark_intervals.mean(axis=1))
    assert traj.landmark_intervals[0, 0] == 0.0
    assert traj.landmark_intervals[-1, 1] == pytest.approx(traj.duration)
    # dwells and motions alternate without gaps
    np.testing.assert_allclose(traj.segment_times[:, 0], traj.landmark_intervals[:-1, 1])
    np.testing.assert_allclose(traj.segment_times[:, 1], traj.landmark_intervals[1:, 0])
    for i, (a, b) in enumerate(traj.landmark_intervals):
        t = np.linspace(a, b, 50)
        q, qd, qdd = traj.sample(t)
        np.testing.assert_allclose(q, np.broadcast_to(LANDMARKS[i], q.shape), atol=1e-12)
        assert np.all(qd == 0.0)
        assert np.all(qdd[:-1] == 0.0)  # at the end of a dwell the next motion starts accelerating


def test_motion_starts_and_ends_at_rest_and_passes_the_waypoints() -> None:
    segments = _segments(LANDMARKS)
    traj = time_parameterize(segments, VMAX, AMAX, 0.0)
    for (a, b), w in zip(traj.segment_times, segments, strict=True):
        assert b > a
        q, qd, _ = traj.sample(np.array([a, b - 1e-12]))
        np.testing.assert_allclose(q, w[[0, -1]], atol=1e-9)
        np.testing.assert_allclose(qd, 0.0, atol=1e-5)
        # the path goes through every waypoint (in order): each is within 1e-6 rad of a sample
        qs, _, _ = traj.sample(np.linspace(a, b, 20001))
        dist = np.linalg.norm(qs[:, None, :] - w[None], axis=2).min(axis=0)
        assert dist.max() < 1e-3


@settings(derandomize=True, max_examples=25, deadline=None)
@given(
    n=st.integers(1, 7),
    points=st.lists(st.integers(2, 9), min_size=1, max_size=3),
    seed=st.integers(0, 2**31 - 1),
    vscale=st.floats(0.2, 3.0),
    ascale=st.floats(0.5, 10.0),
)
def test_limits_hold_under_dense_resampling(
    n: int, points: list[int], seed: int, vscale: float, ascale: float
) -> None:
    rng = np.random.default_rng(seed)
    segments = []
    start = rng.uniform(-2, 2, n)
    for k in points:
        w = np.vstack([start, rng.uniform(-2, 2, (k - 1, n))])
        segments.append(w)
        start = w[-1]
    vmax = vscale * rng.uniform(0.5, 1.5, n)
    amax = ascale * rng.uniform(0.5, 1.5, n)
    traj = time_parameterize(segments, vmax, amax, 0.1)

    t = traj.sample_times(min(5000.0, 60000.0 / traj.duration))  # ≥ 100 samples per TOPPRA interval
    q, qd, qdd = traj.sample(t)
    assert np.isfinite(q).all() and np.isfinite(qd).all() and np.isfinite(qdd).all()
    assert np.max(np.abs(qd) / vmax) <= 1 + 1e-3
    assert np.max(np.abs(qdd) / amax) <= 1 + 1e-3
    # the sampled q̇ and q̈ are the derivatives of the sampled q and q̇: trapezoidal integration,
    # whose error is bounded by dt²·max|q̈|/4 per step for q and by dt·(jump of q̈)/2 where q̈ jumps
    dt = np.diff(t)[:, None]
    step_q = np.diff(q, axis=0) - 0.5 * dt * (qd[1:] + qd[:-1])
    assert np.all(np.abs(step_q) <= 0.25 * dt**2 * amax * 1.01 + 1e-12)
    drift = np.cumsum(np.diff(qd, axis=0) - 0.5 * dt * (qdd[1:] + qdd[:-1]), axis=0)
    variation = np.sum(np.abs(np.diff(qdd, axis=0)), axis=0)
    assert np.all(np.abs(drift) <= 0.5 * dt.max() * variation + 1e-9)
    np.testing.assert_allclose(traj.sample(traj.duration)[0][0], segments[-1][-1], atol=1e-9)


def test_default_grid_and_fixed_grid_keep_the_limits_on_a_long_path() -> None:
    rng = np.random.default_rng(3)
    landmarks = rng.uniform(-1.5, 1.5, (8, 3))
    for gridpoints in (None, 20):
        traj = time_parameterize(_segments(landmarks, k=10), VMAX, AMAX, 0.2, gridpoints=gridpoints)
        rv, ra = _dense_ratios(traj, VMAX, AMAX, 4000.0)
        assert rv <= 1 + 2e-4 and ra <= 1 + 2e-4
        assert max(rv, ra) > 0.99  # time-optimal: some limit is reached


def test_vectorised_evaluation_matches_toppras_parametrizer() -> None:
    traj = time_parameterize(_segments(LANDMARKS), VMAX, AMAX, 0.2)
    motions = [p for p in traj._pieces if isinstance(p, timing._Motion)]
    assert len(motions) == len(LANDMARKS) - 1
    for motion in motions:
        t = np.linspace(0.0, motion.duration, 1001)
        for order, value in enumerate(motion.evaluate(t)):
            np.testing.assert_allclose(value, motion.reference(t, order), rtol=1e-9, atol=1e-9)


def test_samples_at_times_in_any_order_are_each_pieces_own_values() -> None:
    """Shuffled times, boundaries among them, give the same values as the same times in order; and
    each time's value is its piece's, evaluated on its own (the later piece at a boundary)."""
    traj = time_parameterize(_segments(LANDMARKS), VMAX, AMAX, 0.2)
    rng = np.random.default_rng(4)
    times = np.concatenate([rng.uniform(0.0, traj.duration, 300), traj.boundaries])
    shuffled = rng.permutation(times.size)
    in_order, any_order = traj.sample(times), traj.sample(times[shuffled])
    for a, b in zip(in_order, any_order, strict=True):
        np.testing.assert_array_equal(a[shuffled], b)
    piece = np.clip(np.searchsorted(traj._starts, times, side="right") - 1, 0, len(traj._pieces) - 1)
    for k in (0, 17, 300, times.size - 1):
        p = traj._pieces[piece[k]]
        local = np.clip(times[k : k + 1] - traj._starts[piece[k]], 0.0, p.duration)
        for value, own in zip(in_order, p.evaluate(local), strict=True):
            np.testing.assert_array_equal(value[k], own[0])


def test_degenerate_segment_takes_no_time() -> None:
    landmarks = np.array([[0.0, 0.0, 0.0], [0.5, 0.5, 0.5], [0.5, 0.5, 0.5], [0.0, 0.2, 0.0]])
    traj = time_parameterize(_segments(landmarks, bump=0.0), VMAX, AMAX, 0.25)
    a, b = traj.segment_times[1]
    assert a == b
    assert traj.landmark_intervals[2, 0] == traj.landmark_intervals[1, 1]
    q, qd, _ = traj.sample(np.linspace(*traj.landmark_intervals[1], 20))
    np.testing.assert_allclose(q, np.broadcast_to(landmarks[1], q.shape))
    assert np.all(qd == 0)


def test_time_scaled_changes_velocities_and_accelerations() -> None:
    traj = time_parameterize(_segments(LANDMARKS), VMAX, AMAX, 0.2)
    fast = traj.time_scaled(0.5)
    assert fast.duration == pytest.approx(0.5 * traj.duration)
    np.testing.assert_allclose(fast.capture_times, 0.5 * traj.capture_times)
    t = np.linspace(0, traj.duration, 777)
    q, qd, qdd = traj.sample(t)
    fq, fqd, fqdd = fast.sample(0.5 * t)
    np.testing.assert_allclose(fq, q, atol=1e-12)
    np.testing.assert_allclose(fqd, 2 * qd, atol=1e-12)
    np.testing.assert_allclose(fqdd, 4 * qdd, atol=1e-12)


def test_csv_round_trip(tmp_path) -> None:
    names = ["shoulder", "elbow", "wrist"]
    traj = time_parameterize(_segments(LANDMARKS), VMAX, AMAX, 0.2, joint_names=names)
    path = traj.to_csv(tmp_path / "trajectory.csv")
    with path.open() as f:
        header = next(csv.reader(f))
    assert header == ["t"] + [f"{p}_{n}" for p in ("q", "qd", "qdd") for n in names]

    data = np.loadtxt(path, delimiter=",", skiprows=1)
    times = traj.sample_times(100.0)
    np.testing.assert_allclose(data[:, 0], times, atol=1e-9)
    assert np.all(np.isin(np.round(traj.boundaries, 9), np.round(data[:, 0], 9)))
    q, qd, qdd = traj.sample(times)
    np.testing.assert_allclose(data[:, 1:], np.hstack([q, qd, qdd]), rtol=1e-10, atol=1e-12)

    back = Trajectory.from_csv(path, landmark_intervals=traj.landmark_intervals)
    assert back.joint_names == tuple(names)
    assert back.duration == pytest.approx(traj.duration, abs=1e-9)
    np.testing.assert_allclose(back.capture_times, traj.capture_times)
    np.testing.assert_allclose(back.segment_times, traj.segment_times)
    t = data[:, 0]
    np.testing.assert_array_equal(np.hstack(back.sample(t)), data[:, 1:])
    # between rows: linear interpolation, close to the original at 100 Hz
    mid = 0.5 * (t[1:] + t[:-1])
    np.testing.assert_allclose(back.sample(mid)[0], traj.sample(mid)[0], atol=2e-3)

    again = tmp_path / "again.csv"
    back.to_csv(again)
    assert again.read_text().splitlines()[0] == path.read_text().splitlines()[0]


def test_bad_inputs_are_rejected_with_context() -> None:
    segments = _segments(LANDMARKS)
    segments[1] = segments[1] + 0.01
    with pytest.raises(ValueError, match="segment 0 ends"):
        time_parameterize(segments, VMAX, AMAX, 0.1)
    with pytest.raises(ValueError, match="velocity_limit"):
        time_parameterize(_segments(LANDMARKS), [1.0, 0.0, 1.0], AMAX, 0.1)
    with pytest.raises(ValueError, match="segment 0"):
        time_parameterize([np.zeros((1, 3)), np.zeros((2, 3))], VMAX, AMAX, 0.1)
    lone = time_parameterize([np.ones((1, 3))], VMAX, AMAX, 0.1)  # a single landmark: its dwell
    assert lone.duration == 0.1 and lone.capture_times.tolist() == [0.05]
    np.testing.assert_array_equal(lone.sample([0.0, 0.1])[0], np.ones((2, 3)))
    with pytest.raises(ValueError, match="dwell_s"):
        time_parameterize(_segments(LANDMARKS), VMAX, AMAX, -1.0)
    traj = time_parameterize(_segments(LANDMARKS), VMAX, AMAX, 0.1)
    with pytest.raises(ValueError, match="times must lie"):
        traj.sample([traj.duration + 1.0])


def test_toppra_failure_raises_solver_error_naming_the_segment(monkeypatch) -> None:
    real = toppra.algorithm.TOPPRA.compute_trajectory
    calls = {"n": 0}

    def fail_on_second(self, sd_start=0, sd_end=0):  # noqa: ANN001, ANN202 - toppra's signature
        calls["n"] += 1
        return None if calls["n"] == 2 else real(self, sd_start, sd_end)

    monkeypatch.setattr(toppra.algorithm.TOPPRA, "compute_trajectory", fail_on_second)
    with pytest.raises(SolverError, match="segment 1: TOPPRA failed"):
        time_parameterize(_segments(LANDMARKS), VMAX, AMAX, 0.1)


def test_from_csv_reads_columns_by_name(tmp_path) -> None:
    path = tmp_path / "interleaved.csv"
    path.write_text("t,q_a,qd_a,qdd_a,q_b,qd_b,qdd_b\n0,1,2,3,4,5,6\n1,2,3,4,5,6,7\n")
    traj = Trajectory.from_csv(path)
    assert traj.joint_names == ("a", "b")
    q, qd, qdd = traj.sample([0.5])
    np.testing.assert_allclose(np.hstack([q, qd, qdd]), [[1.5, 4.5, 2.5, 5.5, 3.5, 6.5]])
    assert traj.capture_times.size == 0
    path.write_text("t,q_a,qd_b,qdd_a\n0,1,2,3\n1,2,3,4\n")
    with pytest.raises(ValueError, match="same joints"):
        Trajectory.from_csv(path)
