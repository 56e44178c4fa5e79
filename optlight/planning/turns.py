"""Whole turns of the capture postures (docs/design.md §6): a revolute joint at θ and at θ + 2πk is
the same posture — the light, the clearances and the view are unchanged — but not the same motion.
The placement solves each capture on its own, so a joint with more than a turn of range can come out
a turn away from its neighbour's or from the start (a UR5's wrist 5.4 rad from the capture before,
20° of light away; a UR3's shoulder_lift at 3.08 rad, 4.65 rad from the start's −1.57 through the
table, where −3.20 rad is 1.63 rad away over the top): a move the trajectory NLP and the transfers
find no way through. :func:`unwrapped_postures` picks the turns once, before the path is built.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from optlight.robot import Robot
from optlight.robot.kinematics import PRISMATIC_JOINTS

Array = NDArray[np.float64]
#: Turns tried at each capture, either way: a joint's range is at most a few turns.
MAX_TURNS = 2


def unwrapped_postures(robot: Robot, thetas: Array, start: Array) -> Array:
    """The capture postures ``thetas`` (M, n) (rad, visiting order) with each revolute joint of range
    above 2π turned by whole turns, within its limits, so that its travel from ``start`` (n,) through
    the captures is least:

        min over k_1 … k_M of |θ_1 + 2πk_1 − s| + Σ_m |θ_m + 2πk_m − θ_{m−1} − 2πk_{m−1}|,

    each joint on its own, by dynamic programming over the |k| ≤ :data:`MAX_TURNS` that keep it within
    its limits (k = 0 is always allowed: a posture the placement gave). The same light poses (forward
    kinematics is 2π-periodic in such a joint); other joints are returned as they are. The way home
    is left to the return transfer: counting it turned a UR5's first transfer through the object."""
    thetas = np.asarray(thetas, float)
    if len(thetas) == 0:
        return thetas.copy()
    revolute = np.array([kind not in PRISMATIC_JOINTS for kind in robot.joint_kinds], bool)
    wraps = revolute & (robot.upper - robot.lower > 2.0 * np.pi)
    turns = 2.0 * np.pi * np.arange(-MAX_TURNS, MAX_TURNS + 1)[:, None]
    candidates = thetas[:, None, :] + turns  # (M, T, n)
    fits = ((candidates >= robot.lower) & (candidates <= robot.upper)) | (turns == 0.0)
    cost = np.where(fits[0], np.abs(candidates[0] - start), np.inf)  # (T, n): least travel to each turn
    came_from = []
    for k in range(1, len(thetas)):
        step = cost[:, None, :] + np.abs(candidates[k][None, :, :] - candidates[k - 1][:, None, :])  # (T, T, n)
        came_from.append(np.argmin(step, axis=0))
        cost = np.where(fits[k], np.min(step, axis=0), np.inf)
    choice = np.empty((len(thetas), thetas.shape[1]), int)
    choice[-1] = np.argmin(cost, axis=0)
    for k in range(len(thetas) - 1, 0, -1):  # back along the least travel
        choice[k - 1] = came_from[k - 1][choice[k], np.arange(thetas.shape[1])]
    chosen = np.take_along_axis(candidates, choice[:, None, :], axis=1)[:, 0, :]
    return np.where(wraps, chosen, thetas)
