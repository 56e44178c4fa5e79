"""Where the robot base would reach the cap: the value a refusal names when the robot reaches no
light clear from where its base is (:class:`~optlight.errors.OutOfReachError`).

The candidates are the problem's base position moved by (dx, dy) on a grid of step
:data:`BASE_STEP_M` within :data:`BASE_SEARCH_M` (height and orientation kept). Each is scored by the
lights of a coarse lattice of the cap (3 zenith rings × 12 azimuths) the generalized IK reaches from
θ_ref with its random restarts (the robot alone, ~10 ms a light); the :data:`BASE_MAPPED` best,
nearest the problem's base first among equals, are built in full (environment and view included) and
get a reachability map (:func:`~optlight.planning.reach.reachability_map`) at
:data:`BASE_MAP_STEP_DEG`; the one with the most clear cells is named. Lengths in metres.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from optlight.errors import OptlightError
from optlight.planning.policy import Reacher
from optlight.planning.reach import reachability_map
from optlight.robot import generalized_ik, load_robot
from optlight.setup import Setup
from optlight.spec import Problem, problem_from_dict

Array = NDArray[np.float64]

#: The base positions tried: the problem's, moved in the horizontal plane by up to this much (m) ...
BASE_SEARCH_M = 0.3
#: ... in steps of this much (m).
BASE_STEP_M = 0.1
#: Of those, how many (most lights reached by the IK first) get a full reachability map.
BASE_MAPPED = 3
#: Steps (deg: zenith, azimuth) of those maps.
BASE_MAP_STEP_DEG = (10.0, 20.0)


@dataclass(frozen=True)
class BaseSuggestion:
    """A base position (m, world) from which the robot reaches ``clear`` of the ``cells`` cells of a
    reachability map of the cap clear of the environment and the camera's view."""

    position: tuple[float, float, float]
    clear: int
    cells: int

    def __str__(self) -> str:
        x, y, z = self.position
        return (
            f"[robot] base_position_m = [{x:.3f}, {y:.3f}, {z:.3f}] reaches {self.clear} of {self.cells} "
            f"lights of the cap clear (reachability map at {BASE_MAP_STEP_DEG[0]:g}° × {BASE_MAP_STEP_DEG[1]:g}°)"
        )


def base_suggestion(setup: Setup) -> BaseSuggestion | None:
    """The base position near the problem's from which the robot reaches the most lights of the cap
    clear (module docstring), or None when none reaches one."""
    problem, sphere = setup.problem, setup.workcell.sphere
    base = np.asarray(problem.robot.base_position_m, float)
    zeniths = np.linspace(sphere.zenith_min, sphere.zenith_max, 3)
    lights = [sphere.position(z, a) for z in zeniths for a in np.arange(12) * (2.0 * np.pi / 12)]
    steps = np.arange(-BASE_SEARCH_M, BASE_SEARCH_M + 1e-9, BASE_STEP_M)
    scored = []
    for dx in steps:
        for dy in steps:
            shift = float(np.hypot(dx, dy))
            if shift > BASE_SEARCH_M + 1e-9 or shift < 1e-9:
                continue
            moved = _with_base(problem, base + [dx, dy, 0.0])
            robot = load_robot(moved)
            reached = sum(
                generalized_ik(robot, sphere, light, robot.theta_ref, **setup.ik).success for light in lights
            )
            if reached:
                scored.append((-reached, shift, moved))
    best: BaseSuggestion | None = None
    for _, _, moved in sorted(scored, key=lambda s: s[:2])[:BASE_MAPPED]:
        try:
            there = Setup.from_problem(moved)
        except OptlightError:  # a base the setup refuses (in the table, its start not clear): no suggestion
            continue
        reach = reachability_map(Reacher(there.workcell, there.solver, there.image_costs), *BASE_MAP_STEP_DEG)
        clear = int(reach.clear.sum())
        if clear and (best is None or clear > best.clear):
            x, y, z = (round(float(v), 3) for v in moved.robot.base_position_m)
            best = BaseSuggestion((x, y, z), clear, int(reach.success.size))
    return best


def base_hint(setup: Setup) -> str:
    """What a refusal adds: the base that works (:func:`base_suggestion`), or that no base within
    :data:`BASE_SEARCH_M` of the problem's does and what else to change."""
    found = base_suggestion(setup)
    if found is not None:
        return f"move the robot base: {found}"
    return (
        f"no robot base within {BASE_SEARCH_M:g} m of [robot] base_position_m reaches a light of the cap clear "
        "either: move the camera ([camera] position_m) or the object ([object] center_m), or widen [light_sphere]"
    )


def _with_base(problem: Problem, position: Array) -> Problem:
    """``problem`` with ``[robot] base_position_m`` set to ``position`` (m, rounded to the mm a
    problem file would hold), validated."""
    data = problem.to_dict()
    data["robot"]["base_position_m"] = [round(float(v), 3) for v in position]
    return problem_from_dict(data, source=problem.source)
