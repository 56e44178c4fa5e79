"""Slower timing where the joint torques would exceed the robot's limits.

The timing (jerk-limited or TOPPRA) bounds joint velocities, accelerations and jerks, not torques.
Inverse dynamics splits the torque into gravity and motion: τ(t) = g(θ) + d(θ, θ̇, θ̈). Timing the
same path with the limits scaled as (√s v, s a, s^{3/2} j) runs it 1/√s times slower, so θ̇ scales by
√s and θ̈ by s, and d, quadratic in θ̇ and linear in θ̈, by s while g does not change. Where the
motion's peak |τ_j| exceeds the margin m·τ_max,j, the scale that brings that peak to the margin is

    s = (m τ_max,j − |g_j|) / (|τ_j| − |g_j|),

taken over the joints and samples in excess; a few rounds settle the peaks that move when the
profile changes shape. Where gravity alone exceeds the limit no timing helps: the motion is
returned as it is and the verification's ``torque`` check refuses it, naming the joint.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

from optlight.motion import Trajectory
from optlight.robot.dynamics import Dynamics

Array = NDArray[np.float64]

#: Fraction of a torque limit the re-timed motion aims at: room for the verification's denser samples.
TORQUE_MARGIN = 0.95
#: Sampling rate (Hz) of the torque estimate: the profiles are smooth at this scale.
RATE_HZ = 250.0
#: Most samples of the estimate: a motion hours long (which the sample-size check refuses after the
#: timing) is estimated more coarsely instead of filling the memory.
MAX_SAMPLES = 200_000
#: Rounds of re-timing before the motion is left to the verification.
ROUNDS = 4
#: Smallest limit scale: a motion at most 1/√0.1 ≈ 3.2× slower. A motion that needs more (a jump
#: between IK branches, a lamp the arm can barely hold) is left to the verification, which names
#: the joint, instead of being stretched without bound.
MIN_SCALE = 0.1


def torque_scale(dynamics: Dynamics, trajectory: Trajectory) -> float:
    """The limit scale s ≤ 1 (module docstring) that brings ``trajectory``'s torques within
    :data:`TORQUE_MARGIN` of the limits; 1 when they are within them or the robot has no limits,
    0 when gravity alone exceeds a limit where the motion exceeds it."""
    limit = dynamics.torque_limit
    if limit is None:
        return 1.0
    q, qd, qdd = trajectory.sample(trajectory.sample_times(min(RATE_HZ, MAX_SAMPLES / trajectory.duration)))
    tau = np.abs(dynamics.torques(q, qd, qdd))
    over = tau > TORQUE_MARGIN * limit
    if not over.any():
        return 1.0
    rows = np.flatnonzero(over.any(axis=1))
    gravity = np.abs(dynamics.torques(q[rows], np.zeros_like(qd[rows]), np.zeros_like(qdd[rows])))
    excess = tau[rows] - gravity
    room = TORQUE_MARGIN * limit - gravity
    mask = over[rows]
    if (room[mask] <= 0).any():
        return 0.0
    return float(np.min(room[mask] / np.maximum(excess[mask], 1e-12)))


def within_torque_limits(timed: Callable[[float], Trajectory], dynamics: Dynamics) -> Trajectory:
    """``timed(s)`` — the motion timed with its limits scaled by s (module docstring) — at the largest
    scale (1, or the few rounds' estimate, not below :data:`MIN_SCALE`) whose torques stay within
    the limits."""
    scale = 1.0
    trajectory = timed(scale)
    for _ in range(ROUNDS):
        step = torque_scale(dynamics, trajectory)
        if step >= 1.0 or scale * step < MIN_SCALE:
            break
        scale *= step
        trajectory = timed(scale)
    return trajectory
