"""Jerk-limited timing: closed-form duration against ruckig, exact derivative maxima, limits and
continuous acceleration under dense resampling, dwells at rest."""

from __future__ import annotations

import numpy as np
import pytest
import ruckig
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.interpolate import CubicSpline

from optlight.planning.chord import chord_path, spline_position_range
from optlight.planning.jerk import (
    JerkLimitedMotion,
    derivative_maxima,
    jerk_limited_timing,
    rest_to_rest_duration,
)
from optlight.planning.timing import time_parameterize

VMAX = np.array([1.0, 1.5, 0.8])
AMAX = np.array([3.0, 2.0, 4.0])
JMAX = np.array([30.0, 20.0, 40.0])
LANDMARKS = np.array([[0.0, 0.0, 0.0], [0.8, -0.5, 0.3], [0.2, 0.4, -0.6], [1.0, 0.1, 0.0]])


def _segments(landmarks: np.ndarray, k: int = 6, bump: float = 0.2) -> list[np.ndarray]:
    s = np.linspace(0.0, 1.0, k)[:, None]
    out = []
    for a, b in zip(landmarks[:-1], landmarks[1:], strict=True):
        w = a + (b - a) * s
        w[:, 0] += bump * np.sin(np.pi * s[:, 0])
        out.append(w)
    return out


def _ruckig_duration(length: float, v: float, a: float, j: float) -> float:
    otg, inp, out = ruckig.Ruckig(1), ruckig.InputParameter(1), ruckig.Trajectory(1)
    inp.current_position, inp.current_velocity, inp.current_acceleration = [0.0], [0.0], [0.0]
    inp.target_position, inp.target_velocity, inp.target_acceleration = [length], [0.0], [0.0]
    inp.max_velocity, inp.max_acceleration, inp.max_jerk = [v], [a], [j]
    otg.calculate(inp, out)
    return float(out.duration)


def test_closed_form_duration_matches_ruckig() -> None:
    rng = np.random.default_rng(1)
    for _ in range(200):  # every regime: cruise or not, acceleration limit reached or not
        length, v, a, j = rng.uniform(0.01, 3), rng.uniform(0.1, 3), rng.uniform(0.1, 10), rng.uniform(0.5, 200)
        assert rest_to_rest_duration(length, v, a, j) == pytest.approx(_ruckig_duration(length, v, a, j), rel=1e-9)


def test_derivative_maxima_are_exact() -> None:
    rng = np.random.default_rng(2)
    s = np.concatenate([[0.0], np.cumsum(rng.uniform(0.05, 0.5, 7))])
    path = CubicSpline(s, rng.uniform(-1, 1, (8, 4)), bc_type="not-a-knot")
    d1, d2, d3 = derivative_maxima(path)
    dense = np.union1d(np.linspace(0.0, s[-1], 400_001), s)  # the knots hold the maxima of |q″|
    for d, k in ((d1, 1), (d2, 2), (d3, 3)):
        sampled = np.abs(path.derivative(k)(dense)).max(axis=0)
        assert np.all(sampled <= d * (1 + 1e-12))  # an upper bound ...
        np.testing.assert_allclose(sampled, d, rtol=1e-6)  # ... that is reached


def test_profile_evaluation_matches_ruckig() -> None:
    path = CubicSpline([0.0, 0.4, 1.1], [[0.0, 0.0], [0.3, -0.2], [0.5, 0.4]], bc_type="not-a-knot")
    motion = JerkLimitedMotion(path, (0.7, 2.0, 15.0), 0)
    assert motion.duration == pytest.approx(motion.reference.duration, rel=1e-12)
    for t in np.linspace(0.0, motion.duration, 37):
        s, sd, sdd, _ = motion.profile(np.array([t]))
        ref = motion.reference.at_time(t)
        np.testing.assert_allclose([s[0], sd[0], sdd[0]], [ref[0][0], ref[1][0], ref[2][0]], atol=1e-12)


def test_dwells_at_rest_and_segments_join_the_landmarks() -> None:
    traj = jerk_limited_timing(_segments(LANDMARKS), VMAX, AMAX, JMAX, 0.3)
    np.testing.assert_allclose(np.diff(traj.landmark_intervals, axis=1).ravel(), 0.3)
    np.testing.assert_allclose(traj.segment_times[:, 0], traj.landmark_intervals[:-1, 1])
    np.testing.assert_allclose(traj.segment_times[:, 1], traj.landmark_intervals[1:, 0])
    for i, (a, b) in enumerate(traj.landmark_intervals):
        q, qd, qdd = traj.sample(np.linspace(a, b, 30))
        np.testing.assert_allclose(q, np.broadcast_to(LANDMARKS[i], q.shape), atol=1e-12)
        assert np.abs(qd).max() < 1e-12 and np.abs(qdd).max() < 1e-9
    # at the end of each motion the acceleration has come back to 0 (no step into the dwell)
    _, _, qdd = traj.sample(traj.segment_times[:, 1] - 1e-9)
    assert np.abs(qdd).max() < 1e-6


def test_a_pickled_trajectory_samples_the_same_without_ruckigs_copy() -> None:
    # What a worker process receives (figures drawn there): the same values, bit for bit.
    import pickle

    traj = jerk_limited_timing(_segments(LANDMARKS), VMAX, AMAX, JMAX, 0.3)
    copy = pickle.loads(pickle.dumps(traj))
    t = np.linspace(0.0, traj.duration, 501)
    for a, b in zip([*traj.sample(t), traj.jerk(t)], [*copy.sample(t), copy.jerk(t)], strict=True):
        np.testing.assert_array_equal(a, b)
    motions = [p for p in copy._pieces if isinstance(p, JerkLimitedMotion)]
    assert len(motions) == len(LANDMARKS) - 1 and all(m.reference is None for m in motions)


def test_same_geometric_path_as_toppra_and_slower_but_continuous() -> None:
    segments = _segments(LANDMARKS)
    jerk = jerk_limited_timing(segments, VMAX, AMAX, JMAX, 0.0)
    toppra = time_parameterize(segments, VMAX, AMAX, 0.0)
    assert jerk.duration >= toppra.duration  # time-optimal under fewer constraints is never slower
    q_jerk = jerk.sample(np.linspace(0, jerk.duration, 4001))[0]
    q_toppra = toppra.sample(np.linspace(0, toppra.duration, 40001))[0]
    gap = np.linalg.norm(q_jerk[:, None, :] - q_toppra[None, ::10, :], axis=2).min(axis=1)
    assert gap.max() < 2e-3  # the same curve in joint space (TOPPRA sampled every ~0.4 mrad)


@settings(derandomize=True, max_examples=25, deadline=None)
@given(
    n=st.integers(1, 7),
    points=st.lists(st.integers(2, 9), min_size=1, max_size=3),
    seed=st.integers(0, 2**31 - 1),
    vscale=st.floats(0.2, 3.0),
    ascale=st.floats(0.5, 10.0),
    jscale=st.floats(5.0, 500.0),
)
@pytest.mark.slow
def test_limits_hold_and_acceleration_is_continuous_under_dense_resampling(
    n: int, points: list[int], seed: int, vscale: float, ascale: float, jscale: float
) -> None:
    rng = np.random.default_rng(seed)
    segments, start = [], rng.uniform(-2, 2, n)
    for k in points:
        w = np.vstack([start, rng.uniform(-2, 2, (k - 1, n))])
        segments.append(w)
        start = w[-1]
    vmax = vscale * rng.uniform(0.5, 1.5, n)
    amax = ascale * rng.uniform(0.5, 1.5, n)
    jmax = jscale * rng.uniform(0.5, 1.5, n)
    traj = jerk_limited_timing(segments, vmax, amax, jmax, 0.1)
    t = traj.sample_times(min(20_000.0, 400_000.0 / traj.duration))
    q, qd, qdd = traj.sample(t)
    jerk = traj.jerk(t)
    assert np.isfinite(q).all() and np.isfinite(jerk).all()
    assert np.max(np.abs(qd) / vmax) <= 1 + 1e-9
    assert np.max(np.abs(qdd) / amax) <= 1 + 1e-9
    assert np.max(np.abs(jerk) / jmax) <= 1 + 1e-9
    # continuity, independently of jerk(): no step of q̈ larger than the jerk limit allows
    dt = np.diff(t)[:, None]
    assert np.all(np.abs(np.diff(qdd, axis=0)) <= jmax * dt * (1 + 1e-6) + 1e-12)
    # q̈ is the derivative of q̇ (trapezoid rule, error ≤ dt²·max|q⃛|/4 per step)
    step = np.diff(qd, axis=0) - 0.5 * dt * (qdd[1:] + qdd[:-1])
    assert np.all(np.abs(step) <= 0.25 * dt**2 * jmax * 1.01 + 1e-12)
    np.testing.assert_allclose(traj.sample(traj.duration)[0][0], segments[-1][-1], atol=1e-9)


def test_bad_limits_are_named() -> None:
    with pytest.raises(ValueError, match="jerk_limit"):
        jerk_limited_timing(_segments(LANDMARKS), VMAX, AMAX, [1.0, -1.0, 1.0], 0.1)
    with pytest.raises(ValueError, match="segment 0 ends"):
        bad = _segments(LANDMARKS)
        bad[1] = bad[1] + 0.01
        jerk_limited_timing(bad, VMAX, AMAX, JMAX, 0.1)
    lone = jerk_limited_timing([np.ones((1, 3))], VMAX, AMAX, JMAX, 0.2)
    assert lone.duration == 0.2 and lone.capture_times.tolist() == [0.1]


#: A segment of a camera-loop re-plan (Panda, rad, rounded to 0.1 mrad): joint 3 on the trajectory
#: NLP's bound, 5 mrad inside its limit 2.8973, at two knots with the path turning on both sides;
#: joint 4 on its bound at the other end.
AT_THE_BOUND = np.array(
    [
        [0.0844, -1.6427, 2.4277, -2.7305, 0.0217, 1.9585, 0.7851],
        [0.1804, -1.6075, 2.4868, -2.7867, 0.0781, 1.9626, 0.7851],
        [0.2752, -1.5673, 2.5463, -2.8373, 0.1395, 1.9576, 0.7851],
        [0.3686, -1.5226, 2.6052, -2.882, 0.2049, 1.9431, 0.7851],
        [0.461, -1.474, 2.6624, -2.921, 0.2732, 1.9192, 0.7851],
        [0.5529, -1.4222, 2.7167, -2.9544, 0.3429, 1.8858, 0.7851],
        [0.6451, -1.3679, 2.7665, -2.9825, 0.4125, 1.8433, 0.7851],
        [0.7382, -1.3117, 2.8105, -3.0058, 0.4805, 1.7922, 0.7851],
        [0.8329, -1.254, 2.8471, -3.025, 0.5455, 1.7335, 0.7851],
        [0.9297, -1.1952, 2.8748, -3.0405, 0.6061, 1.6682, 0.7851],
        [1.0287, -1.1358, 2.8923, -3.053, 0.6613, 1.5979, 0.7851],
        [1.2576, -1.0319, 2.8923, -3.0668, 0.7654, 1.4339, 0.7851],
        [1.4162, -0.9944, 2.8685, -3.0668, 0.8219, 1.3235, 0.7851],
        [1.5739, -0.9545, 2.8258, -3.0668, 0.8645, 1.2146, 0.7851],
        [1.7292, -0.9128, 2.764, -3.0668, 0.8949, 1.1109, 0.7851],
        [1.8795, -0.8671, 2.6821, -3.0668, 0.9145, 1.0166, 0.7851],
        [2.0202, -0.8116, 2.5786, -3.0668, 0.9248, 0.9385, 0.7851],
        [2.1425, -0.7342, 2.4539, -3.0668, 0.9285, 0.889, 0.7851],
        [2.2282, -0.617, 2.3205, -3.0668, 0.9285, 0.8882, 0.7851],
        [2.2864, -0.4797, 2.2028, -3.0631, 0.9291, 0.9243, 0.7851],
    ]
)
#: The Panda's joint limits (rad), and its published velocity, acceleration and jerk limits.
LOWER = np.array([-2.8973, -1.7628, -2.8973, -3.0718, -2.8973, -0.0175, -2.8973])
UPPER = np.array([2.8973, 1.7628, 2.8973, -0.0698, 2.8973, 3.7525, 2.8973])
PANDA_V = np.array([2.175, 2.175, 2.175, 2.175, 2.61, 2.61, 2.61])
PANDA_A = np.array([15.0, 7.5, 10.0, 12.5, 15.0, 20.0, 20.0])
PANDA_J = np.full(7, 7500.0)


def test_spline_position_range_is_the_range_of_the_spline() -> None:
    rng = np.random.default_rng(3)
    w = np.cumsum(rng.normal(size=(12, 3)), axis=0)
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(w, axis=0), axis=1))])
    low, high = spline_position_range(s, w)
    spline = CubicSpline(s, w, bc_type="not-a-knot")
    for i in range(len(s) - 1):
        dense = spline(np.linspace(s[i], s[i + 1], 20001))
        np.testing.assert_allclose(high[i], dense.max(axis=0), atol=1e-7)
        np.testing.assert_allclose(low[i], dense.min(axis=0), atol=1e-7)


def test_the_timed_path_keeps_the_joint_limits_where_its_spline_bulged() -> None:
    """Through the waypoints alone the spline passes joint 3's limit (by 1 mrad with these rounded
    knots, 6 mrad with the NLP's) between the two knots on the bound; with the position bounds the path gets chord midpoints there, keeps every waypoint,
    and the timed trajectory, densely resampled, stays within the limit."""
    w = AT_THE_BOUND
    s, _ = chord_path(w)
    assert spline_position_range(s, w)[1].max(axis=0)[2] > UPPER[2] + 1e-3
    s2, w2 = chord_path(w, (LOWER, UPPER))
    assert len(w2) > len(w) and all(np.isclose(w2, q).all(axis=1).any() for q in w)
    low, high = spline_position_range(s2, w2)
    assert (low >= LOWER).all() and (high <= UPPER).all()
    for timed, limits in (
        (jerk_limited_timing, (PANDA_V, PANDA_A, PANDA_J)),
        (time_parameterize, (PANDA_V, PANDA_A)),
    ):
        trajectory = timed([w], *limits, 0.1, position_bounds=(LOWER, UPPER))
        q = trajectory.sample(np.linspace(0.0, trajectory.duration, 40001))[0]
        assert (q <= UPPER + 1e-9).all() and (q >= LOWER - 1e-9).all(), timed.__name__
        unbounded = timed([w], *limits, 0.1)
        assert unbounded.sample(np.linspace(0.0, unbounded.duration, 40001))[0][:, 2].max() > UPPER[2]


def test_rest_to_rest_moves_are_the_slowest_joints_double_s_time() -> None:
    """ruckig's time-optimal multi-joint moves from rest to rest take the slowest joint's double-S
    time, which the closed form gives joint by joint; no jerk-limited timing of the same stops beats it."""
    from optlight.planning.jerk import rest_to_rest_moves

    rng = np.random.default_rng(4)
    postures = rng.uniform(-1.0, 1.0, (6, 3))
    v, a, j = np.array([1.0, 2.0, 3.0]), np.array([5.0, 6.0, 7.0]), np.array([50.0, 60.0, 70.0])
    moves = rest_to_rest_moves(postures, v, a, j)
    closed = rest_to_rest_duration(np.abs(np.diff(postures, axis=0)), v, a, j).max(axis=1)
    np.testing.assert_allclose(moves, closed, rtol=1e-9)
    segments = [np.linspace(p, q, 5) for p, q in zip(postures[:-1], postures[1:], strict=True)]
    timed = jerk_limited_timing(segments, v, a, j, 0.0)
    assert np.all(np.diff(timed.segment_times, axis=1)[:, 0] >= moves - 1e-9)
