"""Jerk-limited timing: closed-form duration against ruckig, exact derivative maxima, limits and
continuous acceleration under dense resampling, dwells at rest."""

from __future__ import annotations

import numpy as np
import pytest
import ruckig
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.interpolate import CubicSpline

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
