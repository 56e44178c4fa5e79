"""Joint-space light placement (docs/design.md §5, the design's NLP): the best light the robot can reach.

Variables: the joint angles θ (n, rad). With a(θ), R(θ) the light's position (m) and rotation from the
symbolic forward kinematics (:attr:`Robot.symbolic_light_pose`) and u(θ) = R_WSᵀ (a(θ) − O) / b the
light's direction in the sphere frame (unit when h = 0):

    min_θ  D̃(a(θ), v)
    s.t.   h(θ) = R(θ)ᵀ (O − a(θ)) − [0, 0, b]ᵀ = 0              on the sphere, aimed at O (docs/design.md §3)
           −sin φ u_x + cos φ u_y = 0,   cos φ u_x + sin φ u_y ≥ 0   in the half-plane of azimuth φ
           cos θ_max ≤ u_z ≤ cos θ_min                             the allowed zenith range
           c(θ) ≥ s,   v(θ) ≥ s                                     clearance, view (environment on)
           lower + m ≤ θ ≤ upper − m                               joint limits less m = LIMIT_MARGIN

``D̃`` is the differentiable objective (:attr:`Objective.function`: smooth max and clip) at the
landmark search's resolution (:func:`optlight.planning.landmarks.search_scene`), so a sphere-space
landmark the robot reaches is a solution of this NLP too. The two azimuth rows are linear in u: the
equality puts the light in the plane through the pole at azimuth φ, the inequality keeps it on the
φ side of the pole (not at φ + π). At the pole (u_x = u_y = 0) every azimuth holds, as on the sphere.

Environment. When the problem's ``[environment] enabled`` is set, the rows of the trajectory NLP's
environment (:class:`~optlight.environment.Environment`) join: the clearance c(θ) (m; robot spheres to
the obstacles minus ``margin``, sphere pairs of the self pairs minus ``self_margin``) and, unless the
view cone is off, the view rows v(θ) (m; signed distance of the robot's spheres to the camera's view
cone minus their radii) — a landmark is a capture, so the view cone is kept clear in both of its
modes (the light's beam onto the object, the view rows' second part, is checked on the placement's
result and held by the clear posture, :class:`ClearPosture`); each row at least s = :data:`~optlight.environment.CAPTURE_SLACK`, so that the trajectory NLP
(rows ≥ 0) starts inside its feasible set (where no light of the azimuth keeps s: on the rows'
bounds, :meth:`LightPlacement._margined`). A landmark whose light the robot only reaches by
colliding or blocking the camera then moves along its azimuth to the best light it reaches clear of
both, exactly as an unreachable one does; the trajectory NLP, which pins its landmark knots, could
not do that itself. The clearance rows are those that can bind, as the trajectory NLP takes them
(:func:`~optlight.planning.trajectory.solve_active_rows`, one posture): those below
:data:`~optlight.planning.trajectory.ACTIVE_DISTANCE` at the warm start, more when the solution
breaks one left out, all in the last solve. With L-BFGS, IPOPT's time per iteration grows with the
rows: of the scaling benchmark's 206 clearance rows among its obstacles, ~26 are near a posture,
so taking only those makes each placement solve markedly cheaper for the same solutions.

Azimuth free. The same solver with both azimuth rows switched off through their bounds
(−∞ ≤ g ≤ ∞): one graph and one ``nlpsol`` per row set, as
:class:`~optlight.planning.landmarks.CapRefiner` switches off its unused separation rows. A second solver would only drop two cheap rows, at the
price of building, and keeping consistent, a second NLP.

Parameters p = (φ, v): the azimuth (rad) and the cast-shadow visibility mask v (P,) at the search
resolution. The mask is fixed during a solve: shadow rays at the warm start's light direction, and
when the mask at the solution differs the NLP is solved once more from the solution with the mask
there (:data:`VISIBILITY_ROUNDS`). The NLP is built once per set of clearance rows (the
objective's graph once for all) and reused for every solve.

Reach boundary. When the light the objective wants is out of reach, the NLP's optimum lies on the
boundary of the reachable set, which is a fold of the kinematics: there the 5-D light task Jacobian
(position and optical axis, over the joints not at a limit) loses rank, the light cannot move outwards,
and a trajectory NLP that pins a landmark there fails (IPOPT: Error_In_Step_Computation, seen on the
default face with a low base; pinned 0.02° inside it converged). So a solution whose Jacobian is
singular (σ_min/σ_max < :data:`SINGULAR_TOL`) is moved :data:`BOUNDARY_MARGIN` back along its meridian,
to the side the generalized IK reaches from the solution, then solved again with the zenith pinned there
(the zenith row's bounds) from the IK's angles, to the NLP's accuracy and with a non-singular Jacobian;
the lower cost wins when both sides qualify. A solution with no such side is not a success.

Reported numbers: ``cost`` is the objective of the NumPy render with shadow rays at the camera's
resolution (as :func:`~optlight.planning.landmarks.exact_cost`), of the light where pinocchio's forward
kinematics puts it; ``max_h_residual`` is |h|∞ (m) from pinocchio, independent of the CasADi mirror.

Modules: :mod:`~optlight.planning.placement.light` (the placement NLP) and
:mod:`~optlight.planning.placement.clear_posture` (:class:`ClearPosture`). This package re-exports
their public names.

Angles are radians, lengths metres.
"""

from __future__ import annotations

from optlight.planning.placement.clear_posture import (
    NEAR_STEP,
    POSE_TOL,
    ClearPosture,
)
from optlight.planning.placement.light import (
    AT_LIMIT,
    BOUNDARY_MARGIN,
    CLEARANCE_TOL,
    CONSTRAINT_TOL,
    H_TOL,
    SINGULAR_TOL,
    SOLVERS_KEPT,
    VISIBILITY_ROUNDS,
    ZENITH_ROW,
    LightPlacement,
    PlacementResult,
)

__all__ = [
    "AT_LIMIT",
    "BOUNDARY_MARGIN",
    "CLEARANCE_TOL",
    "CONSTRAINT_TOL",
    "ClearPosture",
    "H_TOL",
    "LightPlacement",
    "NEAR_STEP",
    "POSE_TOL",
    "PlacementResult",
    "SINGULAR_TOL",
    "SOLVERS_KEPT",
    "VISIBILITY_ROUNDS",
    "ZENITH_ROW",
]
