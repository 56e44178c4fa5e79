"""Time-optimal timing of a joint-space path through the landmarks (docs/design.md §6), with TOPPRA.

This is the only module of optlight that imports ``toppra`` (upstream may drop its Python package);
everything else sees a :class:`~optlight.motion.Trajectory`. The jerk-limited timing
(:mod:`optlight.planning.jerk`) is its peer: both time the same path and assemble the same type.

The path is given as segments: segment i is a (K_i, n) array of joint waypoints from landmark i to
landmark i+1, consecutive segments sharing their end and start point. The robot

1. dwells ``dwell_s`` at landmark 0 (the exposure),
2. moves along segment 0, starting and ending at rest (zero joint velocity),
3. dwells at landmark 1, … , moves along the last segment, dwells at the last landmark.

Geometric path of a segment: the not-a-knot cubic spline q(s) through the waypoints q_k over the
cumulative chord parameter, kept within the joint position bounds (:mod:`optlight.planning.chord`).

Timing of a segment: TOPPRA (reachability analysis, seidel solver) maximises the path speed ṡ subject
to |q'(s) ṡ| ≤ v_max and |q''(s) ṡ² + q'(s) s̈| ≤ a_max at the gridpoints s_0 < … < s_N, with
ṡ = 0 at both ends, and ``ParametrizeConstAccel`` turns the result into a trajectory with constant
s̈ = u_i on each interval, so ṡ² = x(s) is linear in s there:

    x(s) = x_i + 2 u_i (s − s_i),   q̇ = q'(s) √x(s),   q̈ = q''(s) x(s) + q'(s) u_i.

The limits hold at the gridpoints by construction but can be exceeded between them (by up to a few
per cent on a coarse grid: q' and q'' vary inside an interval). We therefore probe every interval at
s-fractions 1/8, 2/8, …, 7/8 with the formulas above, halve every interval where a limit is exceeded
by more than :data:`LIMIT_SLACK` and time the segment again, at most :data:`MAX_REFINEMENTS` times.
On random paths the dense-resampled excess then stays near 1e-4. The ``ParametrizeConstAccel``
trajectory is evaluated vectorised by :class:`_Motion` from TOPPRA's gridpoints and path speeds
(toppra's own evaluation loops over the times in Python).
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike, NDArray

if TYPE_CHECKING:
    import toppra

from optlight.errors import SolverError
from optlight.motion import Piece, Trajectory, assemble_trajectory, check_segments, positive_limits
from optlight.planning.chord import as_bounds, chord_path

__all__ = ["time_parameterize"]

Array = NDArray[np.float64]

#: Relative excess over a velocity or acceleration limit accepted between gridpoints (the
#: verification allows 1e-3).
LIMIT_SLACK = 1e-4
#: Largest number of times the grid of a segment is refined where the limits are exceeded.
MAX_REFINEMENTS = 6

#: Grid intervals are kept longer than this fraction of the segment's chord length.
MIN_SPACING_FRACTION = 1e-5

_PROBE_FRACTIONS = np.arange(1, 8) / 8

# toppra logs a warning for every failure we turn into a SolverError, and INFO for every success.
logging.getLogger("toppra").setLevel(logging.ERROR)  # set before toppra is imported, kept after


class _Motion:
    """One segment timed by TOPPRA: the path q(s) and the ``ParametrizeConstAccel`` parametrization
    of the gridpoints s_i and path speeds ṡ_i = v_i, evaluated vectorised:

        t_{i+1} = t_i + 2 Δ_i / (v_i + v_{i+1}),   u_i = (v_{i+1}² − v_i²) / (2 Δ_i),
        on [t_i, t_{i+1}]: ṡ = v_i + u_i τ, s = s_i + v_i τ + u_i τ²/2  (τ = t − t_i),
        q = q(s), q̇ = q'(s) ṡ, q̈ = q''(s) ṡ² + q'(s) u_i.

    ``reference`` is toppra's own ``ParametrizeConstAccel`` trajectory (same values, evaluated one
    time at a time in Python); the tests compare the two.
    """

    def __init__(
        self, path: toppra.SplineInterpolator, gridpoints: Array, speeds: Array, reference: object
    ) -> None:
        self.path = path
        self.s = np.asarray(gridpoints, float)
        self.v = np.asarray(speeds, float)
        ds = np.diff(self.s)
        self.u = (self.v[1:] ** 2 - self.v[:-1] ** 2) / (2 * ds)
        self.t = np.concatenate([[0.0], np.cumsum(2 * ds / (self.v[:-1] + self.v[1:]))])
        self.reference = reference

    @property
    def duration(self) -> float:
        return float(self.t[-1])

    def evaluate(self, t: Array) -> tuple[Array, Array, Array]:
        i = np.clip(np.searchsorted(self.t, t, side="right") - 1, 0, self.u.size - 1)
        tau = t - self.t[i]
        u = self.u[i]
        sd = self.v[i] + u * tau
        s = np.clip(self.s[i] + self.v[i] * tau + 0.5 * u * tau**2, self.s[0], self.s[-1])
        d1 = self.path(s, 1)
        return self.path(s, 0), d1 * sd[:, None], self.path(s, 2) * (sd**2)[:, None] + d1 * u[:, None]

    def jerk(self, t: Array) -> Array:
        """q⃛ = q‴(s) ṡ³ + 3 q″(s) ṡ s̈ inside an interval (s⃛ = 0 there; s̈ steps at the gridpoints,
        where q̈ jumps and q⃛ has an impulse this does not represent)."""
        i = np.clip(np.searchsorted(self.t, t, side="right") - 1, 0, self.u.size - 1)
        tau = t - self.t[i]
        u = self.u[i]
        sd = self.v[i] + u * tau
        s = np.clip(self.s[i] + self.v[i] * tau + 0.5 * u * tau**2, self.s[0], self.s[-1])
        d3 = self.path.cspldd.derivative()(s)
        return d3 * (sd**3)[:, None] + 3 * self.path(s, 2) * (sd * u)[:, None]



def time_parameterize(
    segments: Sequence[ArrayLike],
    velocity_limit: ArrayLike,
    acceleration_limit: ArrayLike,
    dwell_s: float,
    *,
    gridpoints: int | None = None,
    joint_names: Sequence[str] | None = None,
    approach: ArrayLike | None = None,
    retreat: ArrayLike | None = None,
    position_bounds: tuple[ArrayLike, ArrayLike] | None = None,
) -> Trajectory:
    """Time the path through the landmarks: rest at every landmark for ``dwell_s`` (s), and move
    along each segment time-optimally under |q̇_j| ≤ velocity_limit_j (rad/s) and
    |q̈_j| ≤ acceleration_limit_j (rad/s²), starting and ending at rest (module docstring).

    Args:
        segments: M−1 arrays of shape (K_i ≥ 2, n), joint waypoints (rad) from landmark i to i+1;
            segment i ends where segment i+1 starts (within :data:`JOINT_TOLERANCE`). A segment
            whose waypoints all coincide gets zero motion time. A single (1, n) array is a single
            landmark: the trajectory is its dwell.
        velocity_limit, acceleration_limit: (n,) positive limits.
        dwell_s: time (s) the robot stays at each landmark, the first and the last included.
        gridpoints: initial number of TOPPRA gridpoints per segment (uniform in s); default: chosen
            by toppra from the path curvature (at least 100). The spline knots are always added and
            the grid is refined where the limits are exceeded between gridpoints.
        joint_names: names of the n joints, kept on the trajectory.
        approach, retreat: (K ≥ 2, n) joint waypoints from the start configuration to the first
            landmark and from the last landmark back, timed like the segments (rest to rest) before
            the first dwell and after the last; None: the trajectory starts (ends) at that dwell.
        position_bounds: (lower, upper) joint limits (rad, each (n,)) the spline of each segment is
            kept within (:func:`chord_path`); None: the waypoints alone.

    Raises:
        ValueError: inconsistent shapes, non-finite values, segments that do not join, bad limits.
        SolverError: TOPPRA failed on a segment (its index and TOPPRA's return code are named), or
            the limits could not be kept between gridpoints after refinement.
    """
    joint_bounds = None if position_bounds is None else as_bounds(position_bounds)

    def segment(index: int, waypoints: Array, n: int) -> Piece | None:
        vmax = positive_limits(velocity_limit, n, "velocity_limit")
        amax = positive_limits(acceleration_limit, n, "acceleration_limit")
        return _time_segment(index, waypoints, vmax, amax, gridpoints, joint_bounds)

    if gridpoints is not None and gridpoints < 2:
        raise ValueError(f"gridpoints must be at least 2, got {gridpoints}")
    n = check_segments(segments)[1]
    positive_limits(velocity_limit, n, "velocity_limit")
    positive_limits(acceleration_limit, n, "acceleration_limit")
    return assemble_trajectory(segments, dwell_s, segment, joint_names, approach=approach, retreat=retreat)



def _time_segment(
    index: int,
    waypoints: Array,
    vmax: Array,
    amax: Array,
    gridpoints: int | None,
    position_bounds: tuple[Array, Array] | None = None,
) -> _Motion | None:
    """TOPPRA on one segment, rest to rest, with the grid refined until the limits hold between
    gridpoints (module docstring); None for a segment without motion."""
    # imported here: the Trajectory type (verify, export, viz) does not need TOPPRA
    import toppra
    import toppra.algorithm
    import toppra.constraint
    from toppra.interpolator import propose_gridpoints

    chord = chord_path(waypoints, position_bounds)
    if chord is None:
        return None
    s, w = chord
    path = toppra.SplineInterpolator(s, w)
    try:
        if gridpoints is None:
            grid = np.asarray(propose_gridpoints(path, max_err_threshold=1e-3, min_nb_points=100), float)
        else:
            grid = np.linspace(0.0, s[-1], gridpoints)
    except ValueError as e:
        raise SolverError(f"segment {index}: toppra could not choose gridpoints ({e})") from e
    # keep every knot (the third derivative of q(s) jumps there); drop grid points crowding a knot:
    # on a very short interval toppra's own rounding of ṡ² (1e-8) is a large error in s̈ = Δṡ²/2Δs
    min_spacing = MIN_SPACING_FRACTION * s[-1]
    nearest = np.min(np.abs(grid[:, None] - s[None, :]), axis=1)
    grid = np.unique(np.concatenate([grid[nearest > min_spacing], s]))
    constraints = [
        toppra.constraint.JointVelocityConstraint(vmax),
        toppra.constraint.JointAccelerationConstraint(amax),
    ]
    for attempt in range(MAX_REFINEMENTS + 1):
        try:
            algorithm = toppra.algorithm.TOPPRA(
                constraints,
                path,
                gridpoints=grid,
                solver_wrapper="seidel",
                parametrizer="ParametrizeConstAccel",
            )
            output = algorithm.compute_trajectory(0.0, 0.0)
        except Exception as e:  # toppra raises ValueError, AssertionError, ToppraError, …
            raise SolverError(f"segment {index}: TOPPRA raised {type(e).__name__}: {e}") from e
        data = algorithm.problem_data
        if output is None or data.sd_vec is None or not np.isfinite(data.sd_vec).all():
            raise SolverError(
                f"segment {index}: TOPPRA failed ({data.return_code.value}) on a path of {len(w)} waypoints "
                f"and {len(grid)} gridpoints; check the limits and that the waypoints are not degenerate"
            )
        excess = _interval_excess(path, grid, np.asarray(data.sd_vec, float) ** 2, vmax, amax)
        bad = excess > LIMIT_SLACK
        split = bad & (np.diff(grid) > 2 * min_spacing)
        if not bad.any():
            motion = _Motion(path, grid, np.asarray(data.sd_vec, float), output)
            if not np.isclose(motion.duration, float(output.duration), rtol=1e-9, atol=1e-12):
                raise SolverError(
                    f"segment {index}: toppra's ParametrizeConstAccel lasts {output.duration} s, "
                    f"its re-evaluation {motion.duration} s (toppra changed?)"
                )
            return motion
        if attempt == MAX_REFINEMENTS or not split.any():
            break
        grid = np.sort(np.concatenate([grid, 0.5 * (grid[:-1] + grid[1:])[split]]))
    raise SolverError(
        f"segment {index}: the timed path exceeds the joint limits by {excess.max():.2%} between gridpoints "
        f"after {attempt} refinements ({len(grid)} gridpoints); the path is too sharp or too short "
        f"({s[-1]:.3g} rad) — add waypoints or merge nearly identical landmarks"
    )


def _interval_excess(
    path: toppra.SplineInterpolator, grid: Array, x: Array, vmax: Array, amax: Array
) -> Array:
    """Per grid interval: max over probes and joints of max(|q̇|/v_max, |q̈|/a_max) − 1 for the
    constant-s̈ parametrization x(s) = ṡ² linear between gridpoints."""
    ds = np.diff(grid)
    u = (x[1:] - x[:-1]) / (2 * ds)
    s = grid[:-1, None] + ds[:, None] * _PROBE_FRACTIONS  # (N, P)
    xs = np.maximum(x[:-1, None] + 2 * u[:, None] * (s - grid[:-1, None]), 0.0)
    d1 = path(s.ravel(), 1).reshape(*s.shape, -1)
    d2 = path(s.ravel(), 2).reshape(*s.shape, -1)
    qd = d1 * np.sqrt(xs)[..., None]
    qdd = d2 * xs[..., None] + d1 * u[:, None, None]
    ratio = np.maximum(np.abs(qd) / vmax, np.abs(qdd) / amax)
    return ratio.max(axis=(1, 2)) - 1.0
