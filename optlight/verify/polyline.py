"""The distance from sampled light positions to the planned path (a polyline of light positions),
exact and fast for the thousands of knots of a plan."""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial import cKDTree

Array = NDArray[np.float64]

#: Points per chunk in the point-to-polyline distance (bounds the memory of the near segments' lists).
_CHUNK = 50_000


def distance_to_polyline(points: ArrayLike, polyline: ArrayLike) -> Array:
    """Euclidean distance (m) from each of the points (P, 3) to the polyline through (K, 3) vertices
    (a single vertex is a point): min over segments [v_i, v_{i+1}] of |p − (v_i + c (v_{i+1} − v_i))|,
    c = clip((p − v_i)·d_i / |d_i|², 0, 1).

    Only the segments that can be nearest are measured: the nearest vertex, at r₀, bounds the
    distance, and a segment with a point within r₀ of p has its start within r₀ + max_i |d_i| of p
    (a k-d tree finds those). Exact, and O(P log K) for the even knots of a plan instead of O(P K),
    which dominates the verification of a plan of hundreds of captures. The long segments (a transfer's) are first cut into
    pieces (:func:`_even_segments`), so that max_i |d_i| does not widen every point's search."""
    points = np.asarray(points, float).reshape(-1, 3)
    v = np.asarray(polyline, float).reshape(-1, 3)
    out = np.full(len(points), np.nan)  # a NaN point or vertex: NaN, which fails the check
    if len(v) == 1 or not np.isfinite(v).all():
        return np.linalg.norm(points - v[0], axis=1) if len(v) == 1 else out
    v = _even_segments(v)
    # a run of equal points (a dwell's) is measured once, at its first
    finite = np.flatnonzero(np.isfinite(points).all(axis=1))
    first, source = equal_runs(points, finite)
    p = points[first]
    a, d = v[:-1], np.diff(v, axis=0)
    dd = np.maximum(np.einsum("ij,ij->i", d, d), 1e-300)
    bound = (cKDTree(v).query(p)[0] + math.sqrt(float(dd.max()))) * (1.0 + 1e-9) + 1e-12  # rounding
    starts = cKDTree(a)
    for s in range(0, len(p), _CHUNK):
        near = starts.query_ball_point(p[s : s + _CHUNK], bound[s : s + _CHUNK])
        counts = np.fromiter(map(len, near), np.int64, len(near))
        segment = np.concatenate(near).astype(np.int64)
        rel = np.repeat(p[s : s + _CHUNK], counts, axis=0) - a[segment]
        c = np.clip(np.einsum("ck,ck->c", rel, d[segment]) / dd[segment], 0.0, 1.0)
        distance = np.linalg.norm(rel - c[:, None] * d[segment], axis=1)
        out[first[s : s + _CHUNK]] = np.minimum.reduceat(distance, np.r_[0, np.cumsum(counts)[:-1]])
    out[finite] = out[source]
    return out


def equal_runs(rows: Array, index: NDArray[np.intp]) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    """The runs of equal consecutive rows among ``rows[index]`` (``index`` increasing): the index of
    each run's first row, and for each entry of ``index`` the first row of its run."""
    if index.size == 0:
        return index, index
    first = index[np.r_[True, (rows[index[1:]] != rows[index[:-1]]).any(axis=1)]]
    return first, first[np.searchsorted(first, index, side="right") - 1]


def _even_segments(v: Array) -> Array:
    """The polyline through the vertices v (K, 3) with every segment longer than twice the median
    (of the non-zero lengths) cut into equal pieces no longer than that: the same points, so the
    same distances to it."""
    lengths = np.linalg.norm(np.diff(v, axis=0), axis=1)
    positive = lengths[lengths > 0]
    if positive.size == 0:
        return v
    pieces = np.ceil(lengths / (2.0 * float(np.median(positive)))).astype(np.int64).clip(min=1)
    if (pieces == 1).all():
        return v
    segment = np.repeat(np.arange(lengths.size), pieces)
    step = np.arange(pieces.sum()) - np.repeat(np.cumsum(pieces) - pieces, pieces)
    fraction = (step / pieces[segment])[:, None]
    return np.vstack([v[segment] + fraction * (v[segment + 1] - v[segment]), v[-1:]])
