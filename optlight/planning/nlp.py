"""Building blocks every NLP of optlight composes: rows, IPOPT options, the run-and-report helper.

The landmark refiners (:mod:`.landmarks`), the joint-space placement and the clear posture
(:mod:`.placement`) and the trajectory NLP (:mod:`.trajectory`) are each a few of these rows under one
cost. Written once here, so that "the light is on the sphere and aimed at O" or "the light is pinned
at a*" means the same expression in every NLP:

- :func:`light_rows` h(θ) = R(θ)ᵀ (O − a(θ)) − [0, 0, b]ᵀ (m, docs/design.md §3), 3 equality rows;
- :func:`pin_rows` t₁ᵀ (a − a*), t₂ᵀ (a − a*) (m): the light at a* to first order on the sphere,
  2 equality rows, with t₁, t₂ from :func:`tangent_basis` at a*;
- :func:`arc_rows` nᵀ(a − O) (on the great circle of normal n, 1 equality) and the two wedge rows
  (n × u₀)ᵀ(a − O) ≥ 0, (u₁ × n)ᵀ(a − O) ≥ 0 (between the arc's end directions u₀, u₁);
- :func:`environment_rows` c(θ) ≥ 0 and v(θ) ≥ 0 (m): the clearance and view rows of an
  :class:`~optlight.environment.Environment`, built once per robot by the environment itself, and
  :func:`selected_rows` such rows at many knots, or only the (knot, row) pairs that can bind;
- :func:`sphere_position` a(θ, φ) on the light sphere, symbolic;
- :func:`knot_bounds` the joint bounds of every NLP whose joint angles become knots of a trajectory.

:func:`ipopt_options` gives IPOPT's settings from the solver configuration (:func:`knot_nlp_options`
those of the NLPs over knots) and :func:`run` calls a
built ``nlpsol`` and returns a typed :class:`Solve`; :func:`knot_derivatives` gives the NLPs over
knots their Hessian of the Lagrangian (:func:`knot_hessian`) and Jacobian of the constraints
(:func:`knot_jacobian`) knot by knot (:class:`KnotRows`); :func:`knot_map` maps a knot
function over the knots, on the cores when there are enough knots. Lengths in metres, angles in
radians.
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import casadi as ca
import numpy as np
from numpy.typing import NDArray

from optlight.geometry import LightSphere, h_residual
from optlight.threads import thread_count

if TYPE_CHECKING:
    from optlight.environment import Environment
    from optlight.robot import Robot
    from optlight.spec import SolverSpec

Array = NDArray[np.float64]
#: A CasADi expression, SX or MX (the stubs type the two apart; every block here takes either).
Symbolic = Any


@dataclass(frozen=True)
class Solve:
    """One IPOPT solve: the solution ``x``, IPOPT's iteration count, return status and success."""

    x: Array
    iterations: int
    status: str
    success: bool


#: Distance (rad or m) the knots keep from the joint limits, so that the spline timed through them
#: stays inside the limits between knots (a knot exactly on a bound let it overshoot by ~2e-6 rad).
LIMIT_MARGIN = 5e-3


def knot_bounds(robot: Robot) -> tuple[Array, Array]:
    """(lower, upper) (n,): the joint limits less :data:`LIMIT_MARGIN`. The placements use them as
    the trajectory NLP does, so a capture posture they find is one the trajectory NLP may keep."""
    return robot.lower + LIMIT_MARGIN, robot.upper - LIMIT_MARGIN


def ipopt_options(solver: SolverSpec, **overrides: Any) -> dict[str, Any]:
    """IPOPT settings from ``[solver]`` (``max_iter``, ``tol``, ``verbose``), with
    ``overrides`` (IPOPT option names with dots written as ``__``, e.g.
    ``ipopt__hessian_approximation="exact"``) on top.

    The default Hessian is L-BFGS: on the default face the landmark refiner needed about as many
    iterations as with the exact one (90 against 80 over 10 seeds) at half the time per iteration,
    the exact Hessian of the P×K histogram graph costing ~2.5 gradients."""
    options: dict[str, Any] = {
        "ipopt.print_level": 5 if solver.verbose else 0,
        "ipopt.sb": "yes",
        "print_time": solver.verbose,
        "ipopt.max_iter": solver.max_iter,
        "ipopt.tol": solver.tol,
        "ipopt.hessian_approximation": "limited-memory",
    }
    options.update({name.replace("__", "."): value for name, value in overrides.items()})
    return options


def knot_nlp_options(solver: SolverSpec, **overrides: Any) -> dict[str, Any]:
    """:func:`ipopt_options` for the NLPs over knots (the trajectory and transfer NLPs): the exact
    Hessian (theirs is :func:`knot_derivatives`'), and MUMPS without its permuting scaling
    (``mumps_permuting_scaling = 0``: MC64's maximum transversal, recomputed at every
    factorization). Their KKT systems hold thousands of clearance rows; on table_wall the scaling
    takes ~30 % of the trajectory NLP's and the transfers' time, and without it they take the same
    iterations to the same knots (to 4e-15 rad) on the built-in problems. The one-posture and
    landmark NLPs keep MUMPS's default: there it changes their way through the iterations."""
    return ipopt_options(
        solver, ipopt__hessian_approximation="exact", ipopt__mumps_permuting_scaling=0, **overrides
    )


def run(nlp: ca.Function, args: dict[str, Any]) -> Solve:
    """Call a built ``nlpsol`` with ``args`` (x0, p, lbx, ubx, lbg, ubg) and report the solve."""
    result = nlp(**args)
    stats = nlp.stats()
    x = np.asarray(result["x"], float).ravel()
    return Solve(
        x, int(stats.get("iter_count", 0)), str(stats.get("return_status", "")), bool(stats["success"])
    )


#: Fewest knots a mapped knot function is split over threads for (:func:`knot_map`).
THREADED_KNOTS = 8


def knot_map(function: ca.Function, count: int) -> ca.Function:
    """``function`` mapped over ``count`` knots, evaluated on :func:`~optlight.threads.thread_count`
    threads (CasADi's "thread" map) when there are at least :data:`THREADED_KNOTS` knots. Each knot
    is evaluated on its own, so the values are those of the serial map; the threads pay where the
    knot rows dominate an NLP: the 576-capture scaling cell's trajectory NLPs spend 70 % of their
    time in the Hessian and the Jacobian of their rows, ~2.7 ms each for 49 knots."""
    threads = thread_count()
    if threads > 1 and count >= THREADED_KNOTS:
        return function.map(count, "thread", threads)
    return function.map(count)


@dataclass(frozen=True)
class KnotRows:
    """Rows of an NLP over knots that each depend on one knot's joint angles: ``function(θ_k, *args)``
    (an SX function, or one that expands to SX; r×1 out) at the knots ``knots`` (columns of the
    NLP's angle matrix), ``args`` its other inputs there (one column per knot each), and ``index``
    (r, len(knots)) the row of g each output is, −1 where it is not a row of g."""

    function: ca.Function
    knots: Sequence[int]
    args: Sequence[Symbolic]
    index: NDArray[np.int64]


def selected_rows(
    function: ca.Function,
    theta: Symbolic,
    knots: Sequence[int],
    offset: int,
    active: NDArray[np.bool_] | None = None,
) -> tuple[Symbolic, KnotRows]:
    """The rows of ``function`` (θ → m rows, no other input) at the columns ``knots`` of the angle
    matrix ``theta`` (n × F) as a block of g from row ``offset``, knot by knot, and their
    :class:`KnotRows`: every row at every knot, or only those where ``active`` (len(knots), m) is
    True. The others are evaluated with the rest (one mapped function) but are not rows of g, so
    IPOPT's KKT system does not carry them."""
    m = function.size1_out(0)
    values = ca.vec(knot_map(function, len(knots))(theta[:, list(knots)]))
    if active is None:
        active = np.ones((len(knots), m), bool)
    if active.shape != (len(knots), m):
        raise ValueError(f"active rows: shape {active.shape}, expected {(len(knots), m)}")
    chosen = np.flatnonzero(active)  # C order over (knot, row): the order vec stacks the map in
    index = np.full(active.shape, -1)
    index.flat[chosen] = offset + np.arange(chosen.size)
    block = values if chosen.size == active.size else values[chosen.tolist()]
    return block, KnotRows(function, list(knots), [], index.T)


def knot_hessian(
    variables: Symbolic, p: Symbolic, f: Symbolic, g_size: int, rows: Sequence[KnotRows]
) -> ca.Function:
    """IPOPT's Hessian of the Lagrangian (``nlpsol``'s ``hess_lag``: x, p, σ, λ → upper triangle) of an
    NLP over the knot angles Θ (n × F, x = vec Θ) whose cost f is quadratic and whose nonlinear rows
    are ``rows`` (the other rows of g linear in x):

        ∇²ₓ L = σ ∇²f + blockdiag_k Σ_rows ∇²_θk (λ_kᵀ g(θ_k)),

    ∇²f a constant matrix, each block n × n the Hessian of one knot's rows, differentiated on the
    knot function's own SX graph. CasADi's own Hessian colours the whole MX graph of the mapped rows
    instead (~40 evaluations of their reverse derivative per Hessian, 45 % of an obstacle NLP's
    time); this is the same matrix (tested against it). Raises ValueError when f is not quadratic."""
    n, count = variables.shape
    x = ca.vec(variables)
    objective = ca.hessian(f, x)[0]
    if ca.depends_on(objective, ca.vertcat(x, p)):
        raise ValueError("knot_hessian: the cost must be quadratic in x, its Hessian free of p")
    sigma, lam = ca.MX.sym("lam_f"), ca.MX.sym("lam_g", g_size)
    padded = ca.vertcat(lam, 0)  # index g_size: the zero multiplier of an output that is not a row
    blocks = [ca.MX(n, n) for _ in range(count)]
    for part in rows:
        if not len(part.knots):
            continue
        index = np.where(part.index < 0, g_size, part.index)
        weights = ca.reshape(padded[index.ravel(order="F").tolist()], index.shape[0], index.shape[1])
        per_knot = knot_map(row_hessian(part.function), len(part.knots))
        for k, block in zip(
            part.knots,
            ca.horzsplit(per_knot(variables[:, list(part.knots)], *part.args, weights), n),
            strict=True,
        ):
            blocks[k] = blocks[k] + block
    hessian = sigma * ca.evalf(objective) + ca.diagcat(*blocks)
    return ca.Function("nlp_hess_l", [x, p, sigma, lam], [ca.triu(hessian)])


def knot_jacobian(variables: Symbolic, p: Symbolic, g: Symbolic, rows: Sequence[KnotRows]) -> ca.Function:
    """IPOPT's Jacobian of the constraints (``nlpsol``'s ``jac_g``: x, p → g, ∂g/∂x) of an NLP over
    the knot angles Θ (n × F, x = vec Θ) whose nonlinear rows are ``rows`` and whose other rows
    are linear in x (their Jacobian a constant):

        ∂g/∂x = Σ_rows blockdiag_k ∂g(θ_k)/∂θ_k  +  the constant rows,

    each block the Jacobian of one knot's rows, differentiated on the knot function's own SX graph
    and mapped over the knots (:func:`knot_map`). CasADi's own Jacobian propagates n directional
    derivatives through the whole mapped graph; this is the same matrix with the same sparsity
    (tested), in ~35 % less time (1.0 against 1.6 ms on a 12-knot table_wall NLP): bit for bit on
    the Panda's NLPs, and within 1 ulp on the xArm7's (a tenth of the entries differ by 4e-16 there,
    and its knots by 2e-15 rad). Raises ValueError when a row no part holds is not linear in x."""
    n = variables.shape[0]
    x = ca.vec(variables)
    held = np.zeros(g.size1(), bool)
    targets, columns, sources, values = [], [], [], []
    offset = 0
    for part in rows:
        if not len(part.knots):
            continue
        jacobian = row_jacobian(part.function)
        pattern = jacobian.sparsity_out(0)
        out_row, out_col = (np.asarray(i, int) for i in pattern.get_triplet())
        # the mapped Jacobians' nonzeros: knot after knot, each in its block's column-major order
        mapped = knot_map(jacobian, len(part.knots))(variables[:, list(part.knots)], *part.args)
        values.append(ca.vec(mapped.nz[:]))  # a column even where the rows are one
        for local, knot in enumerate(part.knots):
            row = part.index[out_row, local]
            kept = row >= 0  # outputs that are not rows of g have no entries
            held[row[kept]] = True
            targets.append(row[kept])
            columns.append(knot * n + out_col[kept])
            sources.append(offset + local * pattern.nnz() + np.flatnonzero(kept))
        offset += pattern.nnz() * len(part.knots)
    rest = np.flatnonzero(~held)
    if rest.size:
        constant = ca.jacobian(g[rest.tolist()], x)
        if ca.depends_on(constant, ca.vertcat(x, p)):
            raise ValueError("knot_jacobian: a row that no KnotRows holds must be linear in x")
        constant = ca.evalf(constant)
        const_row, const_col = (np.asarray(i, int) for i in constant.sparsity().get_triplet())
        values.append(ca.vec(ca.MX(ca.DM(constant.nonzeros()))))
        targets.append(rest[const_row])
        columns.append(const_col)
        sources.append(offset + np.arange(constant.nnz()))
    target, column, source = (np.concatenate(a).astype(int) for a in (targets, columns, sources))
    pattern, mapping = ca.Sparsity.triplet(g.size1(), x.size1(), target.tolist(), column.tolist(), True)
    order = np.empty(len(mapping), int)
    order[np.asarray(mapping, int)] = np.arange(len(mapping))  # nonzero j of the pattern is entry order[j]
    nonzeros = ca.vertcat(*values)[source[order].tolist()]
    return ca.Function("nlp_jac_g", [x, p], [g, ca.MX(pattern, nonzeros)])


def knot_derivatives(variables: Symbolic, p: Symbolic, f: Symbolic, g: Symbolic, rows: Sequence[KnotRows]) -> dict[str, ca.Function]:
    """``nlpsol``'s options ``hess_lag`` (:func:`knot_hessian`) and ``jac_g`` (:func:`knot_jacobian`)
    of an NLP over knots: both derivatives knot by knot, on the knot functions' own graphs."""
    return {
        "hess_lag": knot_hessian(variables, p, f, g.size1(), rows),
        "jac_g": knot_jacobian(variables, p, g, rows),
    }


def _on_sx(function: ca.Function) -> tuple[ca.Function, ca.SX, list[ca.SX]]:
    """A knot function as SX (expanded when it is MX) and SX symbols for its inputs: θ (its first)
    and the others, for :func:`row_jacobian` and :func:`row_hessian` to differentiate."""
    sx = function.expand() if function.is_a("MXFunction") else function
    theta = ca.SX.sym("theta", sx.size1_in(0))
    return sx, theta, [ca.SX.sym(f"arg{i}", sx.sparsity_in(i)) for i in range(1, sx.n_in())]


@functools.lru_cache(maxsize=64)
def row_jacobian(function: ca.Function) -> ca.Function:
    """(θ, *args) → ∂ function(θ, *args) / ∂θ (r × n, θ its first input), on the function's SX graph;
    built once per function, as :func:`row_hessian`."""
    sx, theta, args = _on_sx(function)
    return ca.Function(f"{sx.name()}_jacobian", [theta, *args], [ca.jacobian(sx(theta, *args), theta)])


@functools.lru_cache(maxsize=64)
def row_hessian(function: ca.Function) -> ca.Function:
    """(θ, *args, λ) → ∇²_θ (λᵀ function(θ, *args)) (n × n, θ its first input), on the function's SX
    graph; built once per function (the knot rows of a robot, an environment's row selection)."""
    sx, theta, args = _on_sx(function)
    out = sx(theta, *args)
    lam = ca.SX.sym("lam", out.size1())
    hessian = ca.hessian(ca.dot(lam, out), theta)[0]
    # no common-subexpression pass: on an environment's rows it takes 0.1 s of a window's build and
    # saves 7 % of the instructions (the same time per evaluation)
    return ca.Function(f"{sx.name()}_hessian", [theta, *args, lam], [hessian])


def light_rows(a: Symbolic, rotation: Symbolic, center: Any, radius: Any) -> Symbolic:
    """h = Rᵀ (O − a) − [0, 0, b]ᵀ (3×1, m): zero iff the light is on the sphere, aimed at O."""
    return h_residual(a, rotation, center, radius)


def pin_rows(a: Symbolic, target: Any, t1: Any, t2: Any) -> Symbolic:
    """[t₁ᵀ (a − a*), t₂ᵀ (a − a*)] (2×1, m): with h = 0 the light is at a* (t₁, t₂ tangent at a*)."""
    return ca.vertcat(ca.dot(t1, a - target), ca.dot(t2, a - target))


def arc_rows(a: Symbolic, center: Any, normal: Any, u0: Any, u1: Any) -> tuple[Symbolic, Symbolic]:
    """(plane, wedge): nᵀ(a − O) (1×1, = 0 on the great circle of normal n) and
    [(n × u₀)ᵀ(a − O), (u₁ × n)ᵀ(a − O)] (2×1, both ≥ 0 between the end directions u₀ and u₁), m."""
    d = a - center
    plane = ca.dot(normal, d)
    wedge = ca.vertcat(ca.dot(ca.cross(normal, u0), d), ca.dot(ca.cross(u1, normal), d))
    return plane, wedge


def environment_rows(
    environment: Environment,
    robot: Robot,
    theta: Symbolic,
    *,
    view: bool = True,
    beam: bool = True,
    clearance_rows: Sequence[int] | None = None,
) -> Symbolic:
    """[c(θ); v(θ)] (m, ≥ 0 is clear): the environment's clearance rows (when it models collisions;
    only ``clearance_rows`` of them when given, e.g. those that can bind), then (``view`` and
    the view cone on) its view rows, the beam's included with ``beam`` (the light on the sphere,
    aimed at the object); the CasADi functions are the environment's, built once per robot and row
    selection."""
    rows = []
    if environment.collisions:
        rows.append(environment.clearance_function(robot, clearance_rows)(theta))
    if view and environment.view_cone is not None:
        rows.append(environment.view_cone_function(robot, beam=beam)(theta))
    return ca.vertcat(*rows) if rows else ca.MX(0, 1)


def sphere_position(sphere: LightSphere, zenith: Symbolic, azimuth: Symbolic) -> Symbolic:
    """a(θ, φ) = O + b R_WS (sinθ cosφ, sinθ sinφ, cosθ), symbolic (m)."""
    d = ca.vertcat(ca.sin(zenith) * ca.cos(azimuth), ca.sin(zenith) * ca.sin(azimuth), ca.cos(zenith))
    return ca.DM(sphere.center) + sphere.radius * ca.mtimes(ca.DM(sphere.rotation), d)


def tangent_basis(u: Array) -> tuple[Array, Array]:
    """Two unit vectors orthogonal to the unit vector u and to each other."""
    helper = np.array([1.0, 0.0, 0.0]) if abs(u[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    t1 = np.cross(u, helper)
    t1 /= np.linalg.norm(t1)
    return t1, np.cross(u, t1)
