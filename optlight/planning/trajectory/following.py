"""Path-following helpers (docs/design.md §6): knots added where the timed spline strays from the
planned path (:func:`follow_planned_path`) and where the chord between two knots' lights sags below
their great-circle arc (:func:`knots_on_arcs`).
"""

from __future__ import annotations

import numpy as np
from scipy.interpolate import CubicSpline

from optlight.planning.timing import chord_path
from optlight.planning.trajectory.optimizer import Array
from optlight.robot.ik import generalized_ik
from optlight.workcell import Workcell

#: import the verifier).
PATH_DEVIATION_M = 2.5e-3
#: Points per knot interval at which the spline's light is measured against the planned path.
DEVIATION_SAMPLES = 8
#: Rounds of knot insertion (each halves the intervals that still stray).
MAX_PATH_REFINEMENTS = 6


def follow_planned_path(cell: Workcell, knots: Array) -> Array:
    """The knots (K, n) (rad) of one segment on the sphere, with knots added where the path the
    timing will follow strays from the planned one.

    The timing follows the not-a-knot cubic spline through the knots in joint space
    (:func:`~optlight.planning.timing.chord_path`); between two knots the light follows that
    spline's forward kinematics, not the chord between the knots' lights, and where the joints move
    a long way for a short light step it leaves the planned path; where the spline leaves the joint
    bounds, chord_path adds the joint-space midpoint of two knots, whose light is off the path too.
    So, per round: every waypoint whose light is more than :data:`PATH_DEVIATION_M` from the
    polyline of the knots' lights is put back on it, and the spline is sampled at
    :data:`DEVIATION_SAMPLES` points per interval; where its light is more than that from the
    polyline, a waypoint is added at the interval's middle, put on it the same way. "Put on it":
    the generalized IK (no restarts) from those joint angles to the light at the polyline's point
    nearest their light, carried radially onto the sphere (within the sag ρ(1 − cos(Δ/2)) of the
    chord between two knots Δ apart, 0.06 mm at 2°), aimed at O; kept when it converges within the
    joint bounds. Halving an interval shrinks the spline's bulge about fourfold; at most
    :data:`MAX_PATH_REFINEMENTS` rounds. What cannot be put back is left as it is (the verification
    reports it)."""
    planned = cell.robot.light_positions(knots)
    if len(planned) < 2:
        return knots
    bounds = (cell.limits.lower, cell.limits.upper)
    w = knots
    for _ in range(MAX_PATH_REFINEMENTS):
        chord = chord_path(w, bounds)
        if chord is None:
            return w
        w = chord[1].copy()
        changed = False
        for i in np.flatnonzero(_polyline_distance(cell.robot.light_positions(w), planned) > PATH_DEVIATION_M):
            on_path = _onto_path(cell, w[i], planned)
            if on_path is not None:
                w[i], changed = on_path, True
        chord = chord_path(w)  # the parameter of the corrected waypoints
        if chord is None:
            return w
        s, w = chord
        spline = CubicSpline(s, w, bc_type="not-a-knot")
        tau = (np.arange(DEVIATION_SAMPLES) + 0.5) / DEVIATION_SAMPLES
        between = s[:-1, None] + tau[None, :] * np.diff(s)[:, None]
        lights = cell.robot.light_positions(spline(between.ravel()))
        stray = _polyline_distance(lights, planned).reshape(between.shape).max(axis=1) > PATH_DEVIATION_M
        for i in np.flatnonzero(stray)[::-1]:  # from the end: the indices before stay valid
            middle = _onto_path(cell, spline(0.5 * (s[i] + s[i + 1])), planned)
            if middle is not None:
                w, changed = np.insert(w, i + 1, middle, axis=0), True
        if not changed:
            return w
    return w


def _onto_path(cell: Workcell, theta: Array, planned: Array) -> Array | None:
    """Joint angles near ``theta`` (rad) whose light is on the planned path (the polyline through
    ``planned`` (K, 3), m, carried onto the sphere), aimed at O, within the joint bounds
    (:func:`follow_planned_path`); None when the IK does not converge there."""
    sphere = cell.sphere
    target = _nearest_on_polyline(cell.robot.light_positions(theta)[0], planned)
    return _light_at(cell, sphere.center + sphere.radius * _unit(target - sphere.center), theta)


def _light_at(cell: Workcell, target: Array, theta: Array) -> Array | None:
    """The generalized IK (no restarts, the joint-limit task) from ``theta`` (rad) to the light at
    ``target`` (m, on the sphere) aimed at O: its joint angles when it converges within the joint
    bounds, else None."""
    settings = {**cell.ik, "secondary": ("joint_limits",)}
    ik = generalized_ik(cell.robot, cell.sphere, target, theta, restarts=False, **settings)
    inside = np.all((ik.theta >= cell.limits.lower) & (ik.theta <= cell.limits.upper))
    return ik.theta if ik.success and inside else None


def _unit(v: Array) -> Array:
    return v / np.linalg.norm(v)


#: Largest sag (m) of the chord between two knots' lights on the sphere below the great-circle arc
#: between them (ρ(1 − cos(Δ/2)) for lights Δ apart) before a knot is added on the arc: half the
#: spline's allowance. The planned path is the polyline of the knots' lights; the
#: light, on the sphere, follows the arc.
ARC_SAG_M = 0.5 * PATH_DEVIATION_M


def knots_on_arcs(cell: Workcell, knots: Array) -> Array:
    """The knots (K, n) (rad) of one segment on the sphere, with knots added on the great-circle
    arc between two consecutive knots whose lights are so far apart that the chord between them
    sags more than :data:`ARC_SAG_M` below the arc (the free path's NLP bounds the joints' steps,
    not the light's: lights 50° apart sag 37 mm at ρ = 0.4 m, and the light on the sphere is that
    far from the planned path). A knot goes at the arc's midpoint, by the generalized IK from the
    joint-space midpoint (:func:`_light_at`), and the halves are split again, at most
    :data:`MAX_PATH_REFINEMENTS` deep; where the IK fails, the interval is left as it is."""
    out = [knots[0]]
    for q0, q1 in zip(knots[:-1], knots[1:], strict=True):
        out += _arc_knots(cell, q0, q1, MAX_PATH_REFINEMENTS)
        out.append(q1)
    return np.array(out)


def _arc_knots(cell: Workcell, q0: Array, q1: Array, depth: int) -> list[Array]:
    """Knots strictly between ``q0`` and ``q1`` on their lights' arc (:func:`knots_on_arcs`)."""
    sphere = cell.sphere
    u0, u1 = (_unit(a - sphere.center) for a in cell.robot.light_positions(np.array([q0, q1])))
    half = 0.5 * float(np.arctan2(np.linalg.norm(np.cross(u0, u1)), u0 @ u1))
    if depth == 0 or sphere.radius * (1.0 - np.cos(half)) <= ARC_SAG_M or np.linalg.norm(u0 + u1) < 1e-9:
        return []
    middle = _light_at(cell, sphere.center + sphere.radius * _unit(u0 + u1), 0.5 * (q0 + q1))
    if middle is None:
        return []
    return [*_arc_knots(cell, q0, middle, depth - 1), middle, *_arc_knots(cell, middle, q1, depth - 1)]


def _polyline_distance(points: Array, polyline: Array) -> Array:
    """Distance (m) from each point (P, 3) to the polyline through the vertices (K ≥ 2, 3):
    min over segments of |p − (v_i + c d_i)|, c = clip((p − v_i)·d_i / |d_i|², 0, 1)."""
    a, d = polyline[:-1], np.diff(polyline, axis=0)
    rel = points[:, None, :] - a[None, :, :]
    c = np.clip(np.einsum("pkj,kj->pk", rel, d) / np.maximum(np.einsum("kj,kj->k", d, d), 1e-300), 0.0, 1.0)
    return np.linalg.norm(rel - c[:, :, None] * d[None, :, :], axis=2).min(axis=1)


def _nearest_on_polyline(point: Array, polyline: Array) -> Array:
    """The point (3,) of the polyline through the vertices (K, 3) nearest ``point`` (3,) (m)."""
    a, d = polyline[:-1], np.diff(polyline, axis=0)
    c = np.clip(np.einsum("ij,ij->i", point - a, d) / np.maximum(np.einsum("ij,ij->i", d, d), 1e-300), 0.0, 1.0)
    nearest = a + c[:, None] * d
    return nearest[np.argmin(np.linalg.norm(nearest - point, axis=1))]
