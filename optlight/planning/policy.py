"""The placement policy: joint angles for the lights, and what to do where the robot cannot have them.

For a light position a* on the sphere:

1. the generalized IK (5-D task, roll free; :func:`~optlight.robot.generalized_ik`) from a start;
2. with an environment, where the IK's joint angles leave a row of the NLPs' sphere model
   (:meth:`Environment.worst_sphere_row`: clearance, and the view cone, a light being a capture)
   below :data:`~optlight.environment.CAPTURE_SLACK` (the trajectory NLP pins the capture, and a
   posture on a row's bound leaves it no interior there), a clear posture for the same light
   (:class:`~optlight.planning.placement.ClearPosture`): the nearest the start, solved from the IK's
   angles; when the IK needed random restarts, from the start, then the one nearest the IK's angles
   (a redundant arm has other postures for one light).

:class:`Reacher` does that (built once per work cell; its NLPs on first need), and the reachability map
and :func:`place_landmarks` both use it. Where no attempt gives clear angles for a landmark,
:func:`place_landmarks` runs the joint-space placement NLP (:class:`LightPlacement`), which moves the
landmark along its azimuth to the best light the robot reaches clear.

Also here: the visiting order of the landmarks and the per-knot IK along a path (the paper's
pipeline, and the trajectory NLP's warm start). Angles in radians, lengths in metres.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from optlight.environment import CAPTURE_SLACK
from optlight.errors import IPOPT_ITERATION_LIMIT, OutOfReachError
from optlight.planning.jerk import rest_to_rest_duration
from optlight.planning.landmarks import Landmark, exact_cost, zenith_grid
from optlight.planning.path import LightPath, azimuth_order, shortest_open_tour
from optlight.planning.placement import ClearPosture, LightPlacement, PlacementResult
from optlight.robot import IKResult, Robot, generalized_ik
from optlight.spec import LandmarksSpec, SolverSpec, TrajectorySpec
from optlight.workcell import ImageCosts, MotionLimits, Workcell

Array = NDArray[np.float64]

#: Said of a placement NLP that stopped at its iteration limit: it may have needed more, not a reach.
ITERATION_LIMIT_HINT = " at [solver] max_iter: raise it if the landmark should be reachable"


@dataclass(frozen=True)
class Attempt:
    """One try at a light: the IK's result, the smallest environment row (m; inf without an
    environment or when the IK failed) and its label at the angles kept, and ``theta`` the clear
    joint angles for the light (the IK's, or a clear posture's), None when there are none."""

    ik: IKResult
    clearance: float
    row: str
    theta: Array | None


@dataclass(frozen=True)
class LandmarkPlacement:
    """The landmarks kept (in the order given, some "placed" by the placement NLP), their joint angles
    (M, n) and what was moved or dropped, in words."""

    landmarks: tuple[Landmark, ...]
    thetas: Array
    warnings: tuple[str, ...]


class Reacher:
    """IK, then a clear posture, for the lights of one work cell (module docstring, steps 1–2); its
    NLPs (clear posture, placement on ``costs``' search scene) with IPOPT's settings from ``solver``."""

    def __init__(self, cell: Workcell, solver: SolverSpec, costs: ImageCosts) -> None:
        self.cell, self.solver, self.costs = cell, solver, costs
        self._posture: ClearPosture | None = None
        self._placement: LightPlacement | None = None

    def attempt(self, position: Array, start: Array, *, restarts: bool = True) -> Attempt:
        """Joint angles that put the light at ``position`` (m, on the sphere), clear of the cell's
        environment, from the IK started at ``start`` (rad)."""
        cell = self.cell
        ik = generalized_ik(cell.robot, cell.sphere, position, start, restarts=restarts, **cell.ik)
        environment = cell.environment
        if not ik.success:
            return Attempt(ik, math.inf, "", None)
        if environment is None:
            return Attempt(ik, math.inf, "", ik.theta)
        clearance, row = environment.worst_sphere_row(cell.robot, ik.theta)
        if clearance >= CAPTURE_SLACK:
            return Attempt(ik, clearance, row, ik.theta)
        if self._posture is None:
            self._posture = ClearPosture(cell, environment, self.solver)
        # The posture nearest the start: a chain of landmarks keeps its posture where a clear one is
        # near it. When the IK went to the light from the start without random restarts, one solve
        # from the IK's angles: they hold the light already, so IPOPT has only the clearance to
        # restore. From the start instead it needs a quarter more iterations, and on rti_dome and
        # yale_grid it ends on postures whose plans move the joints 4–13 % more (same landmarks). A
        # second solve, nearest the IK's angles, would have the same rows and the same starting
        # point: on eight problems it never succeeds where that one has failed (0 of 299). A
        # restart's angles may be on another branch of the arm (3.1 rad from θ_ref at the default
        # cell's light at zenith 22°, azimuth 320°), where IPOPT found no clear posture and from the
        # start it did: then from the start, and failing that from the IK's angles.
        tries: list[tuple[Array, Array | None]]
        if ik.restarts == 0:
            tries = [(start, ik.theta)]
        else:
            tries = [(start, None), (ik.theta, None)]
        for anchor, warm in tries:
            found = self._posture.solve(position, anchor, warm=warm)
            if found is not None:
                return Attempt(ik, found[1], found[2], found[0])
        return Attempt(ik, clearance, row, None)

    @property
    def placement(self) -> LightPlacement:
        """The joint-space placement NLP of the cell, built on first use."""
        if self._placement is None:
            self._placement = LightPlacement(self.cell, self.costs, self.solver)
        return self._placement


#: What to do with a landmark the robot cannot reach clear: ``rule(landmark, attempts, previous)``,
#: with the attempts best first (reached before not; then the larger clearance, or the smaller IK
#: residual) and the previous landmark's joint angles, gives (the landmark that replaces it, its
#: clear joint angles, a note saying what moved where and why) or, when there is none, a sentence
#: saying what was tried. :class:`AzimuthPlacement` by default; a light set brings its own
#: (:class:`optlight.planning.set_landmarks.SetReplacement`).
Replacement = Callable[[Landmark, Sequence[Attempt], Array], tuple[Landmark, Array, str] | str]


def place_landmarks(
    reacher: Reacher,
    spec: LandmarksSpec,
    landmarks: Sequence[Landmark],
    *,
    replacement: Replacement | None = None,
) -> LandmarkPlacement:
    """Joint angles at each landmark: :meth:`Reacher.attempt` chained from the previous landmark's
    angles, then from θ_ref. Where neither attempt gives clear angles, ``replacement`` (by default
    :class:`AzimuthPlacement`: the best light the robot reaches clear on the landmark's azimuth) puts
    another light in its place, with a warning that says how far it moved and why.

    Raises :class:`OutOfReachError` naming the first landmark neither reaches (with both reasons),
    unless ``spec.allow_partial`` (``[landmarks]``), which drops it with a warning.
    """
    chain = PlacementChain(reacher, spec, replacement=replacement)
    for lm in landmarks:
        chain.add(lm)
    return chain.finish()


class PlacementChain:
    """:func:`place_landmarks` one landmark at a time, in their order: :meth:`add` places the next
    (from the previous one's angles), :meth:`finish` ends the chain (its backward pass). The
    placement of a landmark needs only the landmarks before it, so a chain can follow a search that
    finds them one by one (:class:`~optlight.pipeline.PlacementAhead`)."""

    def __init__(self, reacher: Reacher, spec: LandmarksSpec, *, replacement: Replacement | None = None):
        self.reacher, self.spec = reacher, spec
        self.rule = replacement if replacement is not None else AzimuthPlacement(reacher)
        self.kept: list[Landmark] = []
        self.thetas: list[Array] = []
        self.notes: list[str] = []
        self.previous = reacher.cell.robot.theta_ref

    def add(self, lm: Landmark) -> None:
        """Place ``lm`` after the landmarks added before it (:func:`place_landmarks`); raises
        :class:`OutOfReachError` as it does."""
        robot = self.reacher.cell.robot
        attempts = []
        for start, restarts in ((self.previous, False), (robot.theta_ref, True)):
            attempts.append(self.reacher.attempt(lm.position, start, restarts=restarts))
            if attempts[-1].theta is not None:
                break
        clear = attempts[-1].theta
        if clear is not None:
            self._keep(lm, clear)
            return
        attempts.sort(key=lambda a: (not a.ik.success, -a.clearance if a.ik.success else a.ik.residual))
        found = self.rule(lm, attempts, self.previous)
        if not isinstance(found, str):
            self._keep(found[0], found[1])
            self.notes.append(f"landmark {lm.index} (azimuth {np.rad2deg(lm.azimuth):.1f}°) {found[2]}")
            return
        best = attempts[0]
        why = (
            f"out of reach of {robot.name}: {best.ik.message}"
            if not best.ik.success
            else f"blocked for {robot.name}: its IK solution brings {best.row} "
            f"{too_close_mm(best.clearance):.1f} mm too close, and no posture near it is clear"
        )
        where = (
            f"landmark {lm.index} (zenith {np.rad2deg(lm.zenith):.1f}°, azimuth "
            f"{np.rad2deg(lm.azimuth):.1f}°) is {why}; {found}"
        )
        if not self.spec.allow_partial:
            raise OutOfReachError(f"{where}; set [landmarks] allow_partial = true to plan the landmarks it reaches")
        self.notes.append(f"dropped {where}")

    def _keep(self, lm: Landmark, theta: Array) -> None:
        self.kept.append(lm)
        self.thetas.append(theta)
        self.previous = theta

    def finish(self) -> LandmarkPlacement:
        """The placement of the landmarks added; raises :class:`OutOfReachError` when none is kept."""
        if not self.kept:
            raise OutOfReachError(f"no landmark is reachable by {self.reacher.cell.robot.name}")
        thetas = _follow_back(self.reacher, self.kept, np.array(self.thetas))
        return LandmarkPlacement(tuple(self.kept), thetas, tuple(self.notes))


def why_moved(robot: Robot, best: Attempt) -> str:
    """Why a landmark moved, from its best attempt: "to be reachable by …" (``robot``) or "to clear
    the environment (… was … mm too close)"."""
    if not best.ik.success:
        return f"to be reachable by {robot.name}"
    return f"to clear the environment ({best.row} was {too_close_mm(best.clearance):.1f} mm too close)"


def too_close_mm(clearance: float) -> float:
    """How far (mm) a row of ``clearance`` (m) falls short of what a capture keeps,
    :data:`~optlight.environment.CAPTURE_SLACK`."""
    return (CAPTURE_SLACK - clearance) * 1e3


def _cheapest_clear(tried: Sequence[PlacementResult]) -> PlacementResult | None:
    """The cheapest success among the placement NLP's results ``tried``; without one, the cheapest
    whose light is clear all the same (:attr:`PlacementResult.clear`: IPOPT stopped at its iteration
    limit on a light the robot holds clear); None when no light is. Found through the camera loop: a
    re-plan's landmark at azimuth 315°, where every start's solve stopped at its iteration limit at
    zenith 25.0°, clear, the light the previous round had placed there."""
    for usable in ([r for r in tried if r.success], [r for r in tried if r.clear]):
        if usable:
            return min(usable, key=lambda r: r.cost)
    return None


#: Zenith spacing (rad, 5°) of the lights on a landmark's azimuth the reacher tries when the
#: placement NLP fails from every start (:class:`AzimuthPlacement`).
SCAN_STEP = math.radians(5.0)


class AzimuthPlacement:
    """The default :data:`Replacement`: the placement NLP on the landmark's azimuth, from the best
    attempt's IK angles, then from the other's, then from the previous capture's; when it succeeds the
    landmark is replaced by the best light the robot reaches clear on that azimuth, kept off the
    singular reach boundary (status "placed", its cost).

    A success on the reach boundary does not end the starts: where one start's branch of the arm runs
    out of reach, another's may reach further, and the cheapest success is kept. Found through the
    camera loop: the bowl's first re-plan placed a landmark at 51.9° on the boundary from one start
    (cost 0.029, the arm in the light's beam, so the re-plan failed verification) where another
    start gave 26.4° (cost 0.0084).

    Where no start succeeds, the cheapest light a start's solve stopped at clear all the same (at
    IPOPT's iteration limit, :func:`_cheapest_clear`). Where none is clear, the lights on the azimuth
    :data:`SCAN_STEP` apart, nearest the landmark's zenith first, are tried by the reacher from the
    previous capture's angles, and the NLP starts again from each clear posture found (with the
    beam's rows when its optimum without them is in the beam, :meth:`_from_clear`) until it
    succeeds; the cheapest clear light of those solves is kept, and failing all of them, the first
    clear posture's light itself (:meth:`_at_clear`). Found through the camera loop: a re-plan
    moved a landmark from zenith 53.6°, where the robot had reached it clear, to 60°, out of reach;
    the NLP from the IK's unconverged angles and from the previous capture's found the azimuth
    infeasible."""

    def __init__(self, reacher: Reacher) -> None:
        self.reacher = reacher

    def __call__(
        self, lm: Landmark, attempts: Sequence[Attempt], previous: Array
    ) -> tuple[Landmark, Array, str] | str:
        placement = self.reacher.placement
        # the previous capture's clear angles last: where the IK failed, its angles can lie far
        # from any posture that holds the light on the sphere, and the NLP fails from them
        starts = [a.ik.theta for a in attempts] + [previous]
        tried = [placement.solve(lm.azimuth, starts[0])]
        for start in starts[1:]:
            done = [r for r in tried if r.success]
            if done and not min(done, key=lambda r: r.cost).on_boundary:
                break
            tried.append(placement.solve(lm.azimuth, start))
        placed = _cheapest_clear(tried)
        nearest_clear: Array | None = None
        if placed is None:
            for theta in self._clear_on_azimuth(lm, previous):
                nearest_clear = theta if nearest_clear is None else nearest_clear
                tried += self._from_clear(lm, theta)
                if tried[-1].success:
                    break
            placed = _cheapest_clear(tried)
        cell = self.reacher.cell
        sphere = cell.sphere
        if placed is None and nearest_clear is not None:
            return self._at_clear(lm, attempts[0], nearest_clear, tried[-1].message)
        if placed is None:
            last = tried[-1]
            clear_of = " clear of the environment" if cell.environment is not None else ""
            return (
                f"nor is any light on its azimuth{clear_of} within zenith "
                f"{np.rad2deg(sphere.zenith_min):.1f}–{np.rad2deg(sphere.zenith_max):.1f}° "
                f"(placement NLP: {last.message}"
                f"{ITERATION_LIMIT_HINT if last.status == IPOPT_ITERATION_LIMIT else ''})"
            )
        moved = replace(
            lm,
            zenith=placed.zenith,
            position=placed.position,
            cost=placed.cost,
            status="placed",
            solver_status=placed.status,
            iterations=lm.iterations + placed.iterations,
            time_s=lm.time_s + placed.time_s,
        )
        before, after = f"{np.rad2deg(lm.zenith):.1f}°", f"{np.rad2deg(placed.zenith):.1f}°"
        how = (
            f"moved from zenith {before} to {after}"
            if before != after
            else f"kept at zenith {before} with the placement's joint angles"
        )
        note = f"{how} {why_moved(cell.robot, attempts[0])} (cost {lm.cost:.3g} -> {placed.cost:.3g}; {placed.message})"
        return moved, placed.theta, note

    def _from_clear(self, lm: Landmark, theta: Array) -> list[PlacementResult]:
        """The placement NLP on ``lm``'s azimuth from the clear posture ``theta``, then, failing
        that, with the beam's rows: without them its optimum can put the arm in the light's beam
        (the check of the result refuses it), and from a posture clear of the beam the NLP holding
        them keeps it out. Found through the camera loop: a re-plan's landmark at azimuth 315°,
        whose only clear posture from the previous capture's was at zenith 60°, from where the NLP
        went to 54° with the arm's upper link 32 mm inside the beam."""
        placed = self.reacher.placement.solve(lm.azimuth, theta)
        if placed.success:
            return [placed]
        return [placed, self.reacher.placement.solve(lm.azimuth, theta, beam=True)]

    def _at_clear(
        self, lm: Landmark, best: Attempt, theta: Array, message: str
    ) -> tuple[Landmark, Array, str]:
        """``lm`` replaced by the light at the clear posture ``theta`` (on its azimuth, the clear
        light nearest its zenith, :meth:`_clear_on_azimuth`), where the placement NLP found no better
        light clear from it (``message``, its last attempt)."""
        cell = self.reacher.cell
        placement = self.reacher.placement
        position = cell.robot.light_pose(theta)[0]
        zenith = float(cell.sphere.angles(position)[0])
        cost = exact_cost(placement.scene, placement.objective, position)
        moved = replace(lm, zenith=zenith, position=position, cost=cost, status="placed", solver_status="")
        note = (
            f"moved from zenith {np.rad2deg(lm.zenith):.1f}° to {np.rad2deg(zenith):.1f}°, the nearest "
            f"clear light on its azimuth, {why_moved(cell.robot, best)} (cost {lm.cost:.3g} -> {cost:.3g}; "
            f"placement NLP: {message})"
        )
        return moved, theta, note

    def _clear_on_azimuth(self, lm: Landmark, previous: Array) -> Iterator[Array]:
        """Clear joint angles holding a light on ``lm``'s azimuth (the reacher from ``previous``,
        no restarts), at the allowed zeniths :data:`SCAN_STEP` apart, nearest ``lm.zenith`` first."""
        sphere = self.reacher.cell.sphere
        zeniths = zenith_grid(sphere, SCAN_STEP)
        for zenith in zeniths[np.argsort(np.abs(zeniths - lm.zenith), kind="stable")]:
            found = self.reacher.attempt(sphere.position(zenith, lm.azimuth), previous, restarts=False).theta
            if found is not None:
                yield found


#: A posture further than this (rad, largest joint) from the next landmark's is searched again from it.
REJOIN_STEP = 1.0


def _follow_back(reacher: Reacher, landmarks: Sequence[Landmark], thetas: Array) -> Array:
    """The chain's backward pass: the first landmarks were placed before the chain had a posture to
    follow (from θ_ref, maybe on another branch). Walking back from the last, a landmark whose
    angles are more than :data:`REJOIN_STEP` from the next one's is reached again from the next one's
    angles (no restarts); the new clear angles replace the old when they are nearer the next's. A
    landmark the placement NLP put (status "placed") keeps its angles: they are that NLP's optimum."""
    thetas = thetas.copy()
    for i in range(len(landmarks) - 2, -1, -1):
        gap = np.abs(thetas[i] - thetas[i + 1]).max()
        if gap <= REJOIN_STEP or landmarks[i].status == "placed":
            continue
        again = reacher.attempt(landmarks[i].position, thetas[i + 1], restarts=False).theta
        if again is not None and np.abs(again - thetas[i + 1]).max() < gap:
            thetas[i] = again
    return thetas


def visiting_order(spec: TrajectorySpec, limits: MotionLimits, placement: LandmarkPlacement) -> NDArray[np.int64]:
    """Azimuth order, or a short open tour on :func:`tour_costs` (``spec.order``, ``[trajectory] order``)."""
    if spec.order == "tour":
        return shortest_open_tour(tour_costs(spec, limits, placement.thetas))
    return azimuth_order([lm.azimuth for lm in placement.landmarks])


def tour_costs(spec: TrajectorySpec, limits: MotionLimits, thetas: NDArray[np.float64]) -> NDArray[np.float64]:
    """(M, M) what a capture tour through the postures ``thetas`` (M, n) minimises between two of them:
    the joint-space distance |θ_a − θ_b|₂ (rad) when the robot stops at each capture; with flying
    captures (``[trajectory] capture``) the time (s) of the move, estimated as the slowest joint's
    time-optimal rest-to-rest move under the velocity, acceleration and jerk limits
    (:func:`~optlight.planning.jerk.rest_to_rest_duration`): a flying acquisition spends time, and a
    joint far from its limits costs less than its share of the distance."""
    step = np.abs(thetas[:, None, :] - thetas[None, :, :])
    if spec.capture != "flying":
        return np.linalg.norm(step, axis=2)
    return rest_to_rest_duration(step, limits.velocity, limits.acceleration, limits.jerk).max(axis=2)


def knot_ik(cell: Workcell, path: LightPath, landmark_thetas: Array) -> tuple[Array, NDArray[np.int64]]:
    """Per-knot generalized IK of ``cell``'s robot on its sphere along the path (the paper's
    pipeline, and the trajectory NLP's warm start), through the landmarks' own joint angles
    ``landmark_thetas`` (M, n, visiting order: the placement's, clear of the environment): a
    landmark knot takes its landmark's angles; an interior knot k of a segment ending at knot k₁
    starts the IK from θ_{k−1} + (θ_{L} − θ_{k−1}) / (k₁ − k + 1),
    a share of the way to the next landmark's angles θ_L, so the chain arrives at the posture the
    placement chose rather than wherever continuation leads. A transfer segment (off the sphere,
    :attr:`LightPath.transfers`) takes the straight line in joint space between its landmarks'
    angles. Returns the (K, n) angles and, per segment (M − 1,), the number of knots where IK did
    not converge."""
    robot = cell.robot
    thetas = np.empty((path.n_knots, robot.n))
    knots = path.landmark_knots
    thetas[knots] = landmark_thetas
    failures = np.zeros(len(path.transfers), dtype=np.int64)
    for s, segment in enumerate(path.segments()):
        goal, last = landmark_thetas[s + 1], segment.stop - 1
        if path.transfers[s]:
            share = np.linspace(0.0, 1.0, last - segment.start + 1)[1:-1, None]
            thetas[segment.start + 1 : last] = landmark_thetas[s] + share * (goal - landmark_thetas[s])
            continue
        for k in range(segment.start + 1, last):
            previous = thetas[k - 1]
            start = previous + (goal - previous) / (last - k + 1)
            # no random restarts: a restart lands on another IK branch, a jump the path cannot make
            result = generalized_ik(robot, cell.sphere, path.positions[k], start, restarts=False, **cell.ik)
            failures[s] += not result.success
            thetas[k] = result.theta
    return thetas, failures
