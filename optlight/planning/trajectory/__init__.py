"""The trajectory NLP (docs/design.md §6): joint angles at every path knot, built once, solved many times.

Variables θ_0 … θ_{K−1} (joint angles, rad). Constraints per knot k, with a_k, R_k the light
position and rotation from the symbolic forward kinematics:

- h(θ_k) = R_kᵀ (O − a_k) − [0, 0, b] = 0 (on the sphere, aimed at O; docs/design.md §3);
- path = "arc": the light stays on its segment's great circle, n_sᵀ (a_k − O) = 0, and between
  the segment's end points (two linear inequalities in a_k); path = "free": on the sphere only;
- landmark knots: the light exactly at the landmark (the two tangent components of a_k − a*);
- the interior knots of a transfer segment (:attr:`LightPath.transfers`) are off the sphere: instead
  of h, the one row (|a_k − O|² − b²) / 2b ≥ 0 (to first order the light's distance outside the
  sphere, m), so the light never comes nearer the object than the captures do;
- joint bounds (minus :data:`~optlight.planning.nlp.LIMIT_MARGIN`), and |θ_{k+1} − θ_k| ≤ max_step per joint;
- with an environment (:mod:`optlight.environment`): clearance c(θ_k) ≥ 0 at every knot (robot
  spheres to obstacles and to each other, margins included) and the view cone kept clear,
  v(θ_k) ≥ 0, at the landmark knots (view "capture") or at every knot (view "path").

Cost Σ_k Σ_j W_j (θ_{k+1,j} − θ_{k,j})² + w Σ_k |θ_k − θ_ref|². With W_j ∝ 1/v_max,j² (the
pipeline's choice, scaled to mean order 1) the first term is the squared time each step takes at the
velocity limits, a smooth stand-in for the motion time TOPPRA will find; the small posture term
settles the null space.
The per-knot constraints are one SX function mapped over the knots, so the graph stays small.

Modules: :mod:`~optlight.planning.trajectory.optimizer` (the NLP, built once),
:mod:`~optlight.planning.trajectory.knots` (solving it over a path, with its retry),
:mod:`~optlight.planning.trajectory.active_rows` (the clearance rows that join),
:mod:`~optlight.planning.trajectory.transfer` (the transfer NLP),
:mod:`~optlight.planning.trajectory.between` (knots added where the arm comes too close between two) and
:mod:`~optlight.planning.trajectory.following` (knots added to follow the planned path). This
package re-exports their public names.
"""

from __future__ import annotations

from optlight.planning.trajectory.active_rows import (
    ACTIVE_DISTANCE,
    ACTIVE_ROUNDS,
    near_rows,
    rows_of,
    solve_active_rows,
)
from optlight.planning.trajectory.between import (
    BETWEEN_PADDING_M,
    BETWEEN_ROUNDS,
    BETWEEN_SAMPLES,
    ClearPath,
    clear_between_knots,
)
from optlight.planning.trajectory.following import (
    ARC_SAG_M,
    DEVIATION_SAMPLES,
    MAX_PATH_REFINEMENTS,
    PATH_DEVIATION_M,
    follow_planned_path,
    knots_on_arcs,
)
from optlight.planning.trajectory.knots import (
    FIRST_TRY_ITER,
    WARM_H_TOL,
    optimize_knots,
)
from optlight.planning.trajectory.optimizer import (
    POSTURE_WEIGHT,
    WARM_MU_INIT,
    TrajectoryNLPResult,
    TrajectoryOptimizer,
    joined_results,
    knot_cost,
    knot_function,
)
from optlight.planning.trajectory.transfer import (
    TRANSFER_PADDING,
    TRANSFER_STEP,
    plan_transfer,
)

__all__ = [
    "ACTIVE_DISTANCE",
    "ACTIVE_ROUNDS",
    "ARC_SAG_M",
    "BETWEEN_PADDING_M",
    "BETWEEN_ROUNDS",
    "BETWEEN_SAMPLES",
    "ClearPath",
    "DEVIATION_SAMPLES",
    "FIRST_TRY_ITER",
    "MAX_PATH_REFINEMENTS",
    "PATH_DEVIATION_M",
    "POSTURE_WEIGHT",
    "TRANSFER_PADDING",
    "TRANSFER_STEP",
    "TrajectoryNLPResult",
    "TrajectoryOptimizer",
    "WARM_H_TOL",
    "WARM_MU_INIT",
    "clear_between_knots",
    "follow_planned_path",
    "joined_results",
    "knot_cost",
    "knot_function",
    "knots_on_arcs",
    "near_rows",
    "optimize_knots",
    "plan_transfer",
    "rows_of",
    "solve_active_rows",
]
