"""``torque``: the joint torques of the motion by inverse dynamics against the robot's published
limits, and their peaks (reported even for a robot without limits)."""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from optlight.verify.collector import Collector, worst_per_joint
from optlight.verify.report import TorqueSummary

Array = NDArray[np.float64]

#: Joint torques of a motion (duck-typed, as :class:`optlight.robot.Dynamics`): ``torques(q, q̇, q̈)``
#: (T, n) N·m, ``torque_limit`` (n,) N·m or None, ``torque_limit_source`` (str).
TorqueModel = Any


def torque_check(
    collector: Collector, dynamics: TorqueModel, q: Array, qd: Array, qdd: Array, names: list[str]
) -> TorqueSummary:
    """``torque``: |τ_j| / τ_max,j ≤ 1 at every sample, τ = ``dynamics.torques(q, q̇, q̈)`` (N·m);
    recorded only when the robot has limits. Returns the peaks per joint either way."""
    tau = np.abs(dynamics.torques(q, qd, qdd))
    peak = worst_per_joint(tau)
    peaks = tuple(float(tau[k, j]) for j, k in enumerate(peak))
    times = tuple(float(collector.t[k]) for k in peak)
    limit = dynamics.torque_limit
    if limit is None:
        return TorqueSummary(tuple(names), peaks, times, None, None, dynamics.torque_limit_source)
    tau_max = np.asarray(limit, float)
    ratio = tau / tau_max
    collector.joint_check(
        "torque",
        "largest |τ_j| / torque_limit_j (inverse dynamics, the lamp included)",
        "",
        ratio,
        np.ones(tau_max.size),
        lambda j, k: (
            f"joint {names[j]}: |τ| = {tau[k, j]:.4g} N·m > its limit {tau_max[j]:.4g} N·m at t = {collector.t[k]:.4f} s"
        ),
        value=lambda j, k: tau[k, j],
        limit=lambda j, k: tau_max[j],
    )
    fraction = tuple(p / float(m) for p, m in zip(peaks, tau_max, strict=True))
    return TorqueSummary(tuple(names), peaks, times, tuple(tau_max.tolist()), fraction, dynamics.torque_limit_source)

