"""The clearance rows that join an NLP (docs/design.md §6, §8): those near binding at the warm
start, then those the solution breaks or nears (:func:`solve_active_rows`), for the trajectory NLP
and the transfer NLP alike.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TypeVar

import numpy as np
from numpy.typing import NDArray

from optlight.planning.trajectory.optimizer import Array
from optlight.workcell import Workcell

#: What an NLP solve of :func:`solve_active_rows` returns.
_Result = TypeVar("_Result")

#: Clearance rows below this (m) at a knot (or at one next to it) join the trajectory NLP
#: (:func:`optimize_knots`) and the transfer NLP (:func:`plan_transfer`) there. Chosen knot by knot,
#: 0.1 m halves the NLP time on the obstacle problems against 0.15 m; a row left out that the
#: solution breaks still joins (:data:`ACTIVE_ROUNDS`).
ACTIVE_DISTANCE = 0.1
#: Solves of the trajectory NLP with the near rows before the last, which has them all.
ACTIVE_ROUNDS = 2


def solve_active_rows(
    cell: Workcell,
    warm: Array,
    solve: Callable[[NDArray[np.bool_] | None, Array], tuple[_Result, Array | None]],
    bound: float = 0.0,
) -> _Result:
    """An NLP over knots solved with only the clearance rows that can bind, knot by knot:
    ``solve(active, start)`` solves it from the knots ``start`` (K, n) with the clearance row i at
    knot k where ``active[k, i]`` ((K, m) over :meth:`Environment.clearance_function`'s rows; None:
    every row at every knot) and returns its result and its knots (None when it failed). First the
    rows below :data:`ACTIVE_DISTANCE` at a knot of ``warm`` or at a neighbour of it
    (:func:`near_rows`); when the solution breaks a row left out (below ``bound``, m, at some
    knot), those and the rows near the solution join, and the NLP is solved again from the
    solution; after :data:`ACTIVE_ROUNDS` such solves, the last has every row at every knot.
    Without clearance rows (no environment, or no collisions modelled): one solve with None.

    Knot by knot, not one row set for all knots: a row near at some knot is far at most others (on
    the collision problem's second window, 817 (knot, row) pairs instead of the 42 rows near
    somewhere at each of its 57 knots, 2,394), and IPOPT's linear algebra grows with the pairs."""
    env, robot = cell.environment, cell.robot
    if env is None or not env.collisions:
        return solve(None, warm)[0]
    active: NDArray[np.bool_] | None = near_rows(env.clearance_values(robot, warm), ACTIVE_DISTANCE)
    for round_ in range(ACTIVE_ROUNDS + 1):
        result, theta = solve(active, warm)
        if active is None or theta is None:
            break
        values = env.clearance_values(robot, theta)
        broken = (values < bound) & ~active
        if not broken.any():
            break
        active = active | broken | near_rows(values, ACTIVE_DISTANCE) if round_ + 1 < ACTIVE_ROUNDS else None
        warm = theta
    return result


def rows_of(active: NDArray[np.bool_]) -> list[int]:
    """The clearance rows (columns of ``active`` (K, m)) that are rows of the NLP at some knot."""
    return [int(i) for i in np.flatnonzero(active.any(axis=0))]


def near_rows(values: Array, distance: float) -> NDArray[np.bool_]:
    """(K, m): the clearance rows (``values`` (K, m), m) below ``distance`` at each knot or at a
    knot next to it: the knots move in a solve, a row's nearest approach with them."""
    near = values < distance
    spread = near.copy()
    spread[1:] |= near[:-1]
    spread[:-1] |= near[1:]
    return spread
