"""The light's path on the sphere: visiting order, great-circle arcs, knots and roll along the path.

Landmarks are joined by great-circle arcs (slerp of unit vectors from O), sampled with knots at most
``knot_spacing`` rad apart. The light's optical axis points at O; its roll is carried along the path
by parallel transport, so it never flips (docs/design.md §3: never build the frame from a × b̂).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import ArrayLike, NDArray

from optlight.geometry import LightSphere, great_circle

Array = NDArray[np.float64]


@dataclass(frozen=True)
class LightPath:
    """Knots of the light along its path, in visiting order.

    ``directions`` (K, 3) unit vectors from O to the light (world), ``positions`` (K, 3) in metres,
    ``rotations`` (K, 3, 3) light frames (z at O, roll by parallel transport), ``order`` (M,) the
    landmark indices in visiting order, ``landmark_knots`` (M,) the knot of each visited landmark.
    Segment ``s`` runs from knot ``landmark_knots[s]`` to ``landmark_knots[s + 1]`` (both included).

    ``transfers`` (M − 1,) marks the segments the light leaves the sphere on: their interior knots
    are joint-space knots (the arm reconfigures between two captures whose great-circle arc it cannot
    follow), and their directions, positions and rotations are the arc the light leaves.
    """

    directions: Array
    positions: Array
    rotations: Array
    order: NDArray[np.int64]
    landmark_knots: NDArray[np.int64]
    transfers: NDArray[np.bool_]

    @property
    def n_knots(self) -> int:
        """Number K of knots."""
        return len(self.positions)

    def segments(self) -> list[slice]:
        """Knot slices from one visited landmark to the next (both ends included)."""
        k = self.landmark_knots
        return [slice(int(k[s]), int(k[s + 1]) + 1) for s in range(len(k) - 1)]

    def on_sphere(self) -> NDArray[np.bool_]:
        """(K,) True at the knots where the light is on the sphere: all but the interior knots of the
        transfer segments."""
        mask = np.ones(self.n_knots, bool)
        for segment, transfer in zip(self.segments(), self.transfers, strict=True):
            if transfer:
                mask[segment.start + 1 : segment.stop - 1] = False
        return mask

    def with_transfers(self, transfers: ArrayLike) -> LightPath:
        """The same knots, with the segments marked in ``transfers`` (M − 1,) off the sphere."""
        mask = np.asarray(transfers, bool)
        if mask.shape != self.transfers.shape:
            raise ValueError(f"transfers has shape {mask.shape}, expected {self.transfers.shape}")
        return replace(self, transfers=mask)

    def knots_between(self, first: int, last: int) -> slice:
        """Knot slice from visited landmark ``first`` to visited landmark ``last`` (both included)."""
        return slice(int(self.landmark_knots[first]), int(self.landmark_knots[last]) + 1)

    def window(self, first: int, last: int) -> LightPath:
        """The part of the path from visited landmark ``first`` to visited landmark ``last`` (both
        included): its knots, segments and transfers, as a path of its own."""
        knots = self.knots_between(first, last)
        return replace(
            self,
            directions=self.directions[knots],
            positions=self.positions[knots],
            rotations=self.rotations[knots],
            order=self.order[first : last + 1],
            landmark_knots=self.landmark_knots[first : last + 1] - knots.start,
            transfers=self.transfers[first:last],
        )

    def windows(self, knots: int) -> list[tuple[int, int]]:
        """The path cut at visited landmarks into windows (first, last) of about ``knots`` knots:
        each window takes whole segments until it has at least ``knots``; the last window takes
        what remains, or joins the one before it when that would leave it less than half as many."""
        cuts = [0]
        for s in range(1, len(self.landmark_knots)):
            if self.landmark_knots[s] - self.landmark_knots[cuts[-1]] >= knots:
                cuts.append(s)
        last = len(self.landmark_knots) - 1
        if cuts[-1] != last:
            if len(cuts) > 1 and self.landmark_knots[last] - self.landmark_knots[cuts[-1]] < knots / 2:
                cuts.pop()
            cuts.append(last)
        if len(cuts) == 1:  # a single landmark: no segment
            cuts.append(last)
        return list(zip(cuts[:-1], cuts[1:], strict=True))

    def arc_lengths(self) -> Array:
        """Angle (rad) travelled on the sphere along each segment."""
        out = []
        for seg in self.segments():
            d = self.directions[seg]
            out.append(float(np.sum(np.arccos(np.clip(np.sum(d[1:] * d[:-1], axis=1), -1.0, 1.0)))))
        return np.asarray(out)


def azimuth_order(azimuths: ArrayLike) -> NDArray[np.int64]:
    """Landmark indices sorted by azimuth (the paper's order)."""
    return np.argsort(np.asarray(azimuths, float), kind="stable")


def shortest_open_tour(distance: ArrayLike, start: int | None = None) -> NDArray[np.int64]:
    """A short open tour through all points of a symmetric distance matrix D (M, M).

    Nearest-neighbour tours from every start (or the given one), each improved by 2-opt segment
    reversals until no reversal shortens it; the shortest is returned. O(M³) per pass, fine for
    the tens of landmarks of an acquisition.
    """
    d = np.asarray(distance, float)
    m = len(d)
    if m <= 2:
        return np.arange(m)
    starts = range(m) if start is None else [start]
    best, best_len = np.arange(m), np.inf
    for s in starts:
        tour = _nearest_neighbour(d, s)
        tour = _two_opt(d, tour, fixed_start=start is not None)
        length = float(d[tour[:-1], tour[1:]].sum())
        if length < best_len - 1e-12:
            best, best_len = tour, length
    return best


def _nearest_neighbour(d: Array, start: int) -> NDArray[np.int64]:
    m = len(d)
    tour = [start]
    free = np.ones(m, bool)
    free[start] = False
    for _ in range(m - 1):
        row = np.where(free, d[tour[-1]], np.inf)
        nxt = int(np.argmin(row))
        tour.append(nxt)
        free[nxt] = False
    return np.asarray(tour)


def _two_opt(d: Array, tour: NDArray[np.int64], fixed_start: bool) -> NDArray[np.int64]:
    """Reverse tour[i:j+1] whenever that shortens the open path; repeat until none does."""
    t = tour.copy()
    m = len(t)
    improved = True
    while improved:
        improved = False
        for i in range(1 if fixed_start else 0, m - 1):
            for j in range(i + 1, m):
                before = (d[t[i - 1], t[i]] if i > 0 else 0.0) + (d[t[j], t[j + 1]] if j < m - 1 else 0.0)
                after = (d[t[i - 1], t[j]] if i > 0 else 0.0) + (d[t[i], t[j + 1]] if j < m - 1 else 0.0)
                if after < before - 1e-12:
                    t[i : j + 1] = t[i : j + 1][::-1]
                    improved = True
    return t


def parallel_transport_frames(directions: ArrayLike, x0: ArrayLike) -> Array:
    """Light frames along a path of unit directions u_k (from O to the light).

    z_k = −u_k (the light looks at O); x_k is x_{k−1} with its z_k component removed, renormalised
    (discrete parallel transport: the roll turns as little as possible, so it never flips).
    Returns (K, 3, 3) rotations with columns x, y, z.
    """
    u = np.asarray(directions, float)
    x = np.asarray(x0, float)
    frames = np.empty((len(u), 3, 3))
    for k, uk in enumerate(u):
        z = -uk
        x = x - (x @ z) * z
        norm = np.linalg.norm(x)
        if norm < 1e-9:
            raise ValueError(f"reference x axis parallel to the optical axis at knot {k}")
        x = x / norm
        frames[k] = np.column_stack([x, np.cross(z, x), z])
    return frames


def build_path(
    sphere: LightSphere,
    landmark_positions: ArrayLike,
    order: Sequence[int] | NDArray[np.int64],
    knot_spacing: float,
    x0: ArrayLike | None = None,
    min_intervals: Sequence[int] | None = None,
) -> LightPath:
    """Great-circle arcs through the landmarks in the given order, knots ≤ ``knot_spacing`` rad apart,
    and segment s (landmark s to s + 1 in visiting order) cut into at least ``min_intervals[s]``
    intervals (a short arc between two postures far apart in joint space needs knots for the arm's
    reconfiguration, not for the light).

    ``x0`` is the light's x axis at the first landmark (default: the sphere's x_S axis, or y_S when
    that is parallel to the optical axis); the roll then follows by parallel transport.
    """
    pts = np.asarray(landmark_positions, float)
    order_arr = np.asarray(order, dtype=np.int64)
    units = (pts - sphere.center) / np.linalg.norm(pts - sphere.center, axis=1, keepdims=True)
    knots = [units[order_arr[0]][None, :]]
    landmark_knots = [0]
    least = (
        np.ones(len(order_arr) - 1, dtype=np.int64) if min_intervals is None else np.asarray(min_intervals)
    )
    for a, b, n in zip(order_arr[:-1], order_arr[1:], least, strict=True):
        omega = float(np.arccos(np.clip(units[a] @ units[b], -1.0, 1.0)))
        arc = great_circle(units[a], units[b], min(knot_spacing, omega / n) if omega > 0.0 else knot_spacing)
        knots.append(arc[1:])
        landmark_knots.append(landmark_knots[-1] + len(arc) - 1)
    directions = np.concatenate(knots)
    if x0 is None:
        z0 = -directions[0]
        x0 = sphere.rotation[:, 0] if abs(sphere.rotation[:, 0] @ z0) < 0.9 else sphere.rotation[:, 1]
    return LightPath(
        directions=directions,
        positions=sphere.center + sphere.radius * directions,
        rotations=parallel_transport_frames(directions, x0),
        order=order_arr,
        landmark_knots=np.asarray(landmark_knots, dtype=np.int64),
        transfers=np.zeros(len(order_arr) - 1, bool),
    )
