"""The timed motion of the robot: a :class:`Trajectory` q(t) through the landmarks, with a dwell at
each (docs/design.md §6).

Every stage after the timing sees only this type: the verification, the exports, the figures and the
preview. A trajectory is a sequence of pieces (a dwell, the motion along a segment, samples read back
from a CSV file, quintic Hermite polynomials through given points), each evaluated in its own local
time. The timing laws build the motion pieces: TOPPRA (:mod:`optlight.planning.timing`),
jerk-limited (:mod:`optlight.planning.jerk`) and flying (:mod:`optlight.planning.flying`, dwells of
zero length), all through :func:`assemble_trajectory`, which joins [approach,] dwell, motion, dwell,
…, dwell[, retreat]. :class:`Exposure` is the camera's exposure and the blur a capture tolerates.
"""

from __future__ import annotations

import csv
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray

Array = NDArray[np.float64]

#: Largest gap (rad, any joint) allowed between the end of a segment and the start of the next.
JOINT_TOLERANCE = 1e-9
#: Times (s) closer than this are one instant when sampling (the CSV writes nanoseconds).
TIME_RESOLUTION = 1e-6


# --------------------------------------------------------------------------------------------
# Pieces: a trajectory is a sequence of pieces, each evaluated in its own local time [0, duration]
# --------------------------------------------------------------------------------------------


class Piece(Protocol):
    @property
    def duration(self) -> float:
        """Length (s) of the piece."""
        ...

    def evaluate(self, t: Array) -> tuple[Array, Array, Array]:
        """q, q̇, q̈ at local times t ∈ [0, duration], each (T, n)."""
        ...

    def jerk(self, t: Array) -> Array:
        """q⃛ (T, n) at local times t ∈ [0, duration] (the right-hand value where it jumps)."""
        ...


@dataclass(frozen=True)
class _Hold:
    """Standing still at q (a dwell)."""

    q: Array
    duration: float

    def evaluate(self, t: Array) -> tuple[Array, Array, Array]:
        q = np.broadcast_to(self.q, (t.size, self.q.size)).copy()
        return q, np.zeros_like(q), np.zeros_like(q)

    def jerk(self, t: Array) -> Array:
        return np.zeros((t.size, self.q.size))


@dataclass(frozen=True)
class _Samples:
    """Samples (t_k, q_k, q̇_k, q̈_k), each quantity interpolated linearly between them."""

    t: Array
    q: Array
    qd: Array
    qdd: Array

    @property
    def duration(self) -> float:
        return float(self.t[-1] - self.t[0])

    def evaluate(self, t: Array) -> tuple[Array, Array, Array]:
        tt = t + self.t[0]
        i = np.clip(np.searchsorted(self.t, tt, side="right") - 1, 0, self.t.size - 2)
        w = ((tt - self.t[i]) / (self.t[i + 1] - self.t[i]))[:, None]
        q, qd, qdd = (a[i] * (1 - w) + a[i + 1] * w for a in (self.q, self.qd, self.qdd))
        return q, qd, qdd

    def jerk(self, t: Array) -> Array:
        """The slope of the linearly interpolated q̈."""
        tt = t + self.t[0]
        i = np.clip(np.searchsorted(self.t, tt, side="right") - 1, 0, self.t.size - 2)
        return (self.qdd[i + 1] - self.qdd[i]) / (self.t[i + 1] - self.t[i])[:, None]


@dataclass(frozen=True)
class _Quintic:
    """Points (t_k, q_k, q̇_k, q̈_k) joined by the quintic Hermite polynomial of each interval: the one
    polynomial of degree 5 with the given q, q̇, q̈ at both ends (what ROS 2's joint_trajectory_controller
    interpolates when positions, velocities and accelerations are all given). With h = t_{k+1} − t_k,
    x = (t − t_k)/h ∈ [0, 1] and the end values scaled by h (v = h q̇, a = h² q̈):

        q(x) = q_0 + v_0 x + a_0 x²/2 + c_3 x³ + c_4 x⁴ + c_5 x⁵,
        c_3 = 10 Δ − 6 v_0 − 4 v_1 − (3 a_0 − a_1)/2,  c_4 = −15 Δ + 8 v_0 + 7 v_1 + (3 a_0 − 2 a_1)/2,
        c_5 = 6 Δ − 3 (v_0 + v_1) − (a_0 − a_1)/2,    Δ = q_1 − q_0.
    """

    t: Array
    q: Array
    qd: Array
    qdd: Array

    @property
    def duration(self) -> float:
        return float(self.t[-1] - self.t[0])

    def _coefficients(self, t: Array) -> tuple[Array, Array, list[Array]]:
        tt = t + self.t[0]
        i = np.clip(np.searchsorted(self.t, tt, side="right") - 1, 0, self.t.size - 2)
        h = (self.t[i + 1] - self.t[i])[:, None]
        x = (tt[:, None] - self.t[i][:, None]) / h
        v0, v1 = self.qd[i] * h, self.qd[i + 1] * h
        a0, a1 = self.qdd[i] * h**2, self.qdd[i + 1] * h**2
        d = self.q[i + 1] - self.q[i]
        c3 = 10 * d - 6 * v0 - 4 * v1 - 0.5 * (3 * a0 - a1)
        c4 = -15 * d + 8 * v0 + 7 * v1 + 0.5 * (3 * a0 - 2 * a1)
        c5 = 6 * d - 3 * (v0 + v1) - 0.5 * (a0 - a1)
        return x, h, [self.q[i], v0, 0.5 * a0, c3, c4, c5]

    def evaluate(self, t: Array) -> tuple[Array, Array, Array]:
        x, h, c = self._coefficients(t)
        q = c[0] + x * (c[1] + x * (c[2] + x * (c[3] + x * (c[4] + x * c[5]))))
        qd = c[1] + x * (2 * c[2] + x * (3 * c[3] + x * (4 * c[4] + x * 5 * c[5])))
        qdd = 2 * c[2] + x * (6 * c[3] + x * (12 * c[4] + x * 20 * c[5]))
        return q, qd / h, qdd / h**2

    def jerk(self, t: Array) -> Array:
        x, h, c = self._coefficients(t)
        return (6 * c[3] + x * (24 * c[4] + x * 60 * c[5])) / h**3


@dataclass(frozen=True)
class _Scaled:
    """A piece run ``factor`` times slower: q(t) = q_p(t/f), q̇ = q̇_p/f, q̈ = q̈_p/f²."""

    piece: Piece
    factor: float

    @property
    def duration(self) -> float:
        return self.piece.duration * self.factor

    def evaluate(self, t: Array) -> tuple[Array, Array, Array]:
        q, qd, qdd = self.piece.evaluate(t / self.factor)
        return q, qd / self.factor, qdd / self.factor**2

    def jerk(self, t: Array) -> Array:
        return self.piece.jerk(t / self.factor) / self.factor**3


# --------------------------------------------------------------------------------------------
# Trajectory
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Exposure:
    """The camera's exposure and the blur a capture tolerates: ``seconds`` T, the largest angle
    ``blur_rad`` (rad) the light may turn about the object's centre during T and the largest distance
    ``blur_m`` (m) it may travel."""

    seconds: float
    blur_rad: float
    blur_m: float

    def __post_init__(self) -> None:
        if not all(np.isfinite(x) and x > 0 for x in (self.seconds, self.blur_rad, self.blur_m)):
            raise ValueError(f"exposure and blur tolerances must be finite and positive, got {self}")



class Trajectory:
    """A timed joint trajectory q(t), t ∈ [0, duration] (s), with the light still at each landmark for
    a dwell, or passing it (a dwell of zero length: flying captures,
    :func:`~optlight.planning.flying.flying_timing`).

    Attributes (all times in seconds from the start):
        landmark_intervals: (M, 2) start and end of the dwell at each landmark.
        capture_times: (M,) middle of each dwell (the instant of a flying capture).
        segment_times: (M−1, 2) start and end of the motion from landmark i to landmark i+1
            (start = end for a segment without motion).
        joint_names: names of the n joints, or None.

    Build one with a timing law (:func:`~optlight.planning.timing.time_parameterize`,
    :func:`~optlight.planning.jerk.jerk_limited_timing`), :meth:`from_csv` or :meth:`from_points`.
    """

    def __init__(
        self,
        pieces: Sequence[Piece],
        landmark_intervals: ArrayLike,
        segment_times: ArrayLike,
        joint_names: Sequence[str] | None = None,
    ) -> None:
        if not pieces:
            raise ValueError("a trajectory needs at least one piece")
        self._pieces = tuple(pieces)
        self._starts = np.concatenate([[0.0], np.cumsum([p.duration for p in self._pieces])])
        self._dof = int(self._pieces[0].evaluate(np.zeros(1))[0].shape[1])
        self.landmark_intervals: Array = np.asarray(landmark_intervals, float).reshape(-1, 2)
        self.segment_times: Array = np.asarray(segment_times, float).reshape(-1, 2)
        if joint_names is not None and len(joint_names) != self._dof:
            raise ValueError(f"{len(joint_names)} joint names for a trajectory of {self._dof} joints")
        self.joint_names: tuple[str, ...] | None = None if joint_names is None else tuple(joint_names)

    @property
    def duration(self) -> float:
        """Total time (s), dwells included."""
        return float(self._starts[-1])

    @property
    def dof(self) -> int:
        """Number n of joints."""
        return self._dof

    @property
    def capture_times(self) -> Array:
        """(M,) exposure times (s): the middle of each landmark's dwell."""
        return self.landmark_intervals.mean(axis=1)

    def trigger_times(self, settle_s: float) -> Array:
        """(M,) camera triggers (s): ``settle_s`` into each dwell, or the instant of a dwell of zero
        length (a flying capture: the light passes the landmark then). ValueError when ``settle_s`` is
        negative or not shorter than a dwell that has a length."""
        lengths = self.landmark_intervals[:, 1] - self.landmark_intervals[:, 0]
        stops = lengths > 0
        if not (settle_s >= 0 and np.all(settle_s < lengths[stops])):
            raise ValueError(
                f"settle_s = {settle_s} s must be ≥ 0 and shorter than every dwell "
                f"({lengths[stops].min(initial=np.inf):.6g} s)"
            )
        return self.landmark_intervals[:, 0] + np.where(stops, settle_s, 0.0)

    def exposure_windows(self, settle_s: float, exposure_s: float) -> Array:
        """(M, 2) start and end (s) of each capture's exposure of ``exposure_s``: from the trigger on
        after a stop (:meth:`trigger_times`), centred on the trigger on the fly, within [0, duration]."""
        triggers = self.trigger_times(settle_s)
        flying = self.landmark_intervals[:, 1] == self.landmark_intervals[:, 0]
        start = triggers - np.where(flying, 0.5 * exposure_s, 0.0)
        return np.clip(np.column_stack([start, start + exposure_s]), 0.0, self.duration)

    @property
    def boundaries(self) -> Array:
        """Sorted times (s) where a dwell or a motion starts or ends, 0 and duration included; times
        closer than :data:`TIME_RESOLUTION` are merged."""
        times = np.concatenate(
            [[0.0, self.duration], self.landmark_intervals.ravel(), self.segment_times.ravel()]
        )
        return _distinct(times)

    def sample_times(self, rate_hz: float) -> Array:
        """Times k/rate_hz from 0 to the end, plus :attr:`boundaries`; a uniform time closer than
        :data:`TIME_RESOLUTION` to a boundary gives way to the boundary."""
        if not rate_hz > 0:
            raise ValueError(f"rate_hz must be positive, got {rate_hz}")
        uniform = np.arange(int(np.floor(self.duration * rate_hz + 1e-9)) + 1) / rate_hz
        edges = self.boundaries
        padded = np.concatenate([[-np.inf], edges, [np.inf]])
        i = np.searchsorted(padded, uniform)
        gap = np.minimum(uniform - padded[i - 1], padded[i] - uniform)
        return np.sort(np.concatenate([uniform[gap > TIME_RESOLUTION], edges]))

    def sample(self, t: ArrayLike) -> tuple[Array, Array, Array]:
        """Joint positions q (rad), velocities q̇ (rad/s), accelerations q̈ (rad/s²) at times t (s).

        ``t`` is a scalar or a 1-D array in [0, duration]; each result has shape (T, n). At a time
        where two pieces meet, the later piece is evaluated (q and q̇ are continuous there; q̈ is too in a
        jerk-limited trajectory, not in a TOPPRA one).
        """
        out = self._evaluate(t, lambda piece, local: piece.evaluate(local), 3)
        return out[0], out[1], out[2]

    def jerk(self, t: ArrayLike) -> Array:
        """Joint jerks q⃛ (rad/s³), shape (T, n), at times t (s), like :meth:`sample`. A
        :func:`~optlight.planning.timing.time_parameterize` (TOPPRA) trajectory gives the value inside
        its constant-s̈ intervals: its q̈ steps between them, which only an impulse of q⃛ could
        represent."""
        return self._evaluate(t, lambda piece, local: (piece.jerk(local),), 1)[0]

    def _evaluate(
        self, t: ArrayLike, method: Callable[[Piece, Array], tuple[Array, ...]], count: int
    ) -> list[Array]:
        """``count`` (T, n) arrays from ``method(piece, local times)`` of the piece holding each time.

        The times are grouped by piece with one stable sort (each piece's times in their given order),
        not one comparison of every time per piece: that was O(T · pieces), 2 s of a 576-capture
        verification."""
        times = np.atleast_1d(np.asarray(t, float))
        if times.ndim != 1:
            raise ValueError(f"times must be a scalar or a 1-D array, got shape {times.shape}")
        if times.size and (
            times.min() < -1e-9 or times.max() > self.duration + 1e-9 or np.isnan(times).any()
        ):
            raise ValueError(f"times must lie in [0, {self.duration:.6g}] s")
        out = [np.empty((times.size, self._dof)) for _ in range(count)]
        index = np.clip(np.searchsorted(self._starts, times, side="right") - 1, 0, len(self._pieces) - 1)
        order = np.argsort(index, kind="stable")
        counts = np.bincount(index, minlength=len(self._pieces))
        first = np.cumsum(counts) - counts
        for k in np.flatnonzero(counts):
            sel = order[first[k] : first[k] + counts[k]]
            piece = self._pieces[k]
            local = np.clip(times[sel] - self._starts[k], 0.0, piece.duration)
            for o, v in zip(out, method(piece, local), strict=True):
                o[sel] = v
        return out

    def time_scaled(self, factor: float) -> Trajectory:
        """The same motion with every time multiplied by ``factor`` (> 0): q_f(t) = q(t/factor),
        so velocities are divided by factor and accelerations by factor². factor < 1 is faster."""
        if not factor > 0:
            raise ValueError(f"factor must be positive, got {factor}")
        return Trajectory(
            [_Scaled(p, factor) for p in self._pieces],
            self.landmark_intervals * factor,
            self.segment_times * factor,
            self.joint_names,
        )

    def to_csv(
        self, path: str | Path, joint_names: Sequence[str] | None = None, *, rate_hz: float = 100.0
    ) -> Path:
        """Write the trajectory sampled at :meth:`sample_times` (``rate_hz`` plus the boundaries).

        Columns: ``t`` (s), then ``q_<joint>`` (rad) for every joint, then ``qd_<joint>`` (rad/s),
        then ``qdd_<joint>`` (rad/s²). Joint names default to :attr:`joint_names`, else j0, j1, ….
        """
        names = _joint_names(joint_names if joint_names is not None else self.joint_names, self._dof)
        t = self.sample_times(rate_hz)
        q, qd, qdd = self.sample(t)
        header = ["t"] + [f"{p}_{n}" for p in ("q", "qd", "qdd") for n in names]
        path = Path(path)
        # one %-format per row, not a format and a csv.writer call per value (3× faster); the same
        # text: '%.12g' formats as f'{v:.12g}' does, and csv.writer ends its rows with \r\n
        row = "%.9f," + ",".join(["%.12g"] * (3 * self._dof)) + "\r\n"
        with path.open("w", newline="") as f:
            csv.writer(f).writerow(header)
            f.write("".join(row % tuple(r) for r in np.column_stack([t, q, qd, qdd]).tolist()))
        return path

    @classmethod
    def from_csv(cls, path: str | Path, *, landmark_intervals: ArrayLike | None = None) -> Trajectory:
        """Read a file written by :meth:`to_csv`; q, q̇, q̈ are interpolated linearly between rows.

        The file does not record the dwells: pass ``landmark_intervals`` (M, 2) (e.g. from plan.json)
        to restore them; :attr:`segment_times` are then the gaps between consecutive dwells.
        """
        path = Path(path)
        with path.open(newline="") as f:
            header = next(csv.reader(f), None)
        if not header or header[0] != "t":
            raise ValueError(
                f"{path}: the first column must be 't', got {header[:1] if header else 'nothing'}"
            )
        columns: dict[str, list[str]] = {"q": [], "qd": [], "qdd": []}
        for name in header[1:]:
            prefix = next((p for p in ("qdd", "qd", "q") if name.startswith(p + "_")), None)
            if prefix is None:
                raise ValueError(f"{path}: column {name!r} is not q_<joint>, qd_<joint> or qdd_<joint>")
            columns[prefix].append(name[len(prefix) + 1 :])
        names = columns["q"]
        if not names or columns["qd"] != names or columns["qdd"] != names:
            raise ValueError(
                f"{path}: the q_, qd_ and qdd_ columns must name the same joints in the same order"
            )
        data = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)
        t = data[:, 0]
        if t.size < 2 or np.any(np.diff(t) <= 0) or abs(t[0]) > 1e-9:
            raise ValueError(f"{path}: times must start at 0 and increase strictly (at least two rows)")
        q, qd, qdd = (data[:, [header.index(f"{p}_{name}") for name in names]] for p in ("q", "qd", "qdd"))
        piece = _Samples(t, q, qd, qdd)
        if landmark_intervals is None:
            intervals = np.zeros((0, 2))
        else:
            intervals = np.asarray(landmark_intervals, float).reshape(-1, 2)
        segments = np.column_stack([intervals[:-1, 1], intervals[1:, 0]])
        return cls([piece], intervals, segments, names)

    @classmethod
    def from_points(
        cls,
        t: ArrayLike,
        q: ArrayLike,
        qd: ArrayLike,
        qdd: ArrayLike,
        *,
        joint_names: Sequence[str] | None = None,
        landmark_intervals: ArrayLike | None = None,
    ) -> Trajectory:
        """The trajectory through points (t_k, q_k, q̇_k, q̈_k) joined by quintic Hermite polynomials
        (:class:`_Quintic`): it reproduces q, q̇, q̈ at every point. ``t`` (K ≥ 2) starts at 0 and
        increases strictly; q, q̇, q̈ are (K, n). ``landmark_intervals`` as in :meth:`from_csv`."""
        times = np.asarray(t, float)
        arrays = [np.asarray(a, float) for a in (q, qd, qdd)]
        if times.ndim != 1 or times.size < 2 or abs(times[0]) > 1e-9 or np.any(np.diff(times) <= 0):
            raise ValueError("point times must start at 0 and increase strictly (at least two points)")
        if any(a.ndim != 2 or a.shape != arrays[0].shape or a.shape[0] != times.size for a in arrays):
            raise ValueError(f"positions, velocities and accelerations must be ({times.size}, n) arrays")
        if not all(np.isfinite(a).all() for a in arrays):
            raise ValueError("positions, velocities and accelerations must be finite")
        intervals = np.zeros((0, 2)) if landmark_intervals is None else np.asarray(landmark_intervals, float)
        intervals = intervals.reshape(-1, 2)
        segments = np.column_stack([intervals[:-1, 1], intervals[1:, 0]])
        return cls([_Quintic(times, *arrays)], intervals, segments, joint_names)


def _distinct(times: Array, tol: float = TIME_RESOLUTION) -> Array:
    """Sorted times with values closer than ``tol`` merged (the earliest kept)."""
    t = np.sort(np.asarray(times, float))
    return t[np.concatenate([[True], np.diff(t) > tol])] if t.size else t


def _joint_names(names: Sequence[str] | None, n: int) -> list[str]:
    if names is None:
        return [f"j{i}" for i in range(n)]
    names = list(names)
    if len(names) != n:
        raise ValueError(f"{len(names)} joint names for {n} joints")
    for name in names:
        if not name or any(c in name for c in ',"\n\r'):
            raise ValueError(f"joint name {name!r} cannot be a CSV column name")
    return names



# --------------------------------------------------------------------------------------------
# Assembly: dwells and the segments' motions, as a timing law times them
# --------------------------------------------------------------------------------------------

#: time_segment(segment index, waypoints (K, n), n) -> the motion along the segment, rest to rest, or
#: None for a segment whose waypoints all coincide.
SegmentTiming = Callable[[int, Array, int], "Piece | None"]


def assemble_trajectory(
    segments: Sequence[ArrayLike],
    dwell_s: float,
    time_segment: SegmentTiming,
    joint_names: Sequence[str] | None = None,
    *,
    approach: ArrayLike | None = None,
    retreat: ArrayLike | None = None,
) -> Trajectory:
    """Check the segments (:func:`check_segments`) and join [approach,] dwell, motion, dwell,
    …, dwell[, retreat]: ``time_segment`` times each segment, the approach (index −1) and the
    retreat (index M − 1) from rest to rest."""
    waypoints, n, lone = check_segments(segments)
    if not (np.isfinite(dwell_s) and dwell_s >= 0):
        raise ValueError(f"dwell_s must be a finite non-negative number, got {dwell_s}")
    first, last = waypoints[0][0], waypoints[-1][-1]
    pieces: list[Piece] = []
    t = 0.0
    if approach is not None:
        path = _transfer(approach, n, "approach")
        if np.max(np.abs(path[-1] - first)) > JOINT_TOLERANCE:
            raise ValueError("the approach does not end at the first landmark")
        motion = time_segment(-1, path, n)
        if motion is not None:
            pieces.append(motion)
            t = motion.duration
    pieces.append(_Hold(first, float(dwell_s)))
    intervals = [(t, t + float(dwell_s))]
    t += float(dwell_s)
    seg_times = []
    for i, w in enumerate([] if lone else waypoints):
        motion = time_segment(i, w, n)
        if motion is not None:
            pieces.append(motion)
        start, t = t, t + (motion.duration if motion is not None else 0.0)
        seg_times.append((start, t))
        pieces.append(_Hold(w[-1], float(dwell_s)))
        intervals.append((t, t + dwell_s))
        t += dwell_s
    if retreat is not None:
        path = _transfer(retreat, n, "retreat")
        if np.max(np.abs(path[0] - last)) > JOINT_TOLERANCE:
            raise ValueError("the retreat does not start at the last landmark")
        motion = time_segment(len(waypoints) - (1 if lone else 0), path, n)
        if motion is not None:
            pieces.append(motion)
    return Trajectory(pieces, intervals, seg_times, joint_names)


def _transfer(waypoints: ArrayLike, n: int, name: str) -> Array:
    """An approach or retreat as a finite (K ≥ 2, n) array, or ValueError naming it."""
    path = np.asarray(waypoints, float)
    if path.ndim != 2 or path.shape[0] < 2 or path.shape[1] != n or not np.isfinite(path).all():
        raise ValueError(f"the {name} must be a finite (K ≥ 2, {n}) array of joint angles, got {path.shape}")
    return path


def check_segments(segments: Sequence[ArrayLike]) -> tuple[list[Array], int, bool]:
    """The segments as (K_i, n) arrays, n, and whether they are a single landmark (one (1, n) array);
    ValueError for bad shapes, non-finite values, or segments that do not join."""
    waypoints = [np.asarray(s, float) for s in segments]
    if not waypoints:
        raise ValueError("at least one segment is needed")
    n = waypoints[0].shape[1] if waypoints[0].ndim == 2 else 0
    lone = len(waypoints) == 1 and waypoints[0].ndim == 2 and waypoints[0].shape[0] == 1  # one landmark
    for i, w in enumerate(waypoints):
        if w.ndim != 2 or w.shape[0] < (1 if lone else 2) or w.shape[1] != n or n == 0:
            raise ValueError(f"segment {i}: expected a (K ≥ 2, {n}) array of waypoints, got shape {w.shape}")
        if not np.isfinite(w).all():
            raise ValueError(f"segment {i}: waypoints are not finite")
    for i in range(len(waypoints) - 1):
        gap = float(np.max(np.abs(waypoints[i][-1] - waypoints[i + 1][0])))
        if gap > JOINT_TOLERANCE:
            raise ValueError(
                f"segment {i} ends at {waypoints[i][-1]} but segment {i + 1} starts at "
                f"{waypoints[i + 1][0]} (gap {gap:.3g} rad)"
            )
    return waypoints, n, lone


def positive_limits(value: ArrayLike, n: int, name: str) -> Array:
    """(n,) finite positive limits from one value or n; ValueError naming ``name`` otherwise."""
    lim = np.asarray(value, float)
    if lim.shape not in ((), (n,)) or not (np.isfinite(lim).all() and (lim > 0).all()):
        raise ValueError(f"{name} must be one or {n} finite positive numbers, got {lim}")
    return np.broadcast_to(lim, (n,)).copy()
