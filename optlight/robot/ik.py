"""Generalized inverse kinematics (paper; docs/design.md §6) for the light.

One iteration, with e and J from the primary task (:mod:`optlight.robot.tasks`) at θ:

    δθ = J# e + (I − J⁺ J) γ,      J# = Jᵀ (J Jᵀ + λ² I)⁻¹,      γ = −Σ_i k_i ∇H_i(θ),

J⁺ = Jᵀ (J Jᵀ + εI)⁻¹ (ε = 1e-12) makes I − J⁺J the null-space projector: the paper's formula with
an undamped projector, so the secondary tasks never disturb the primary one (:func:`null_space_step`).
λ² = λ₀² + 0.03 |e|²: Levenberg–Marquardt damping that shrinks with the error, so the last iterations
are Gauss–Newton and converge quadratically (λ₀² = ``damping``, [solver] ik_damping).

Joint limits: a joint at a limit whose step points outwards is frozen for that iteration (its column
of J and its γ entry are zeroed and the step recomputed); every iterate is clipped into
[lower, upper]; the step is scaled so that max_i |δθ_i| ≤ ``max_step``.

When the error stops decreasing (a local minimum of |e|, typically against joint limits or on the
wrong elbow/wrist branch) the solver restarts from the best (smallest |e|) of 8 seeded random
configurations, within the same iteration budget. Success means |e|² < ``tol`` *and* θ within the limits, checked explicitly on the
returned θ.
"""

from __future__ import annotations

import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Literal, cast

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.linalg.lapack import dgesv as _gesv

from optlight.geometry import LightSphere
from optlight.robot.loading import Robot
from optlight.robot.tasks import (
    SECONDARY_TASKS,
    KinematicState,
    LightPointingTask,
    LightPoseTask,
    PrimaryTask,
    SecondaryTask,
)
from optlight.spec import SolverSpec

Array = NDArray[np.float64]

_SPEC = SolverSpec()

#: Null-space gains k of the secondary tasks named without a weight (see :mod:`optlight.robot.tasks`).
DEFAULT_GAINS: dict[str, float] = {
    "joint_limits": _SPEC.ik_joint_limit_gain,
    "manipulability": 0.01,
    "posture": 0.02,
}

#: Levenberg–Marquardt factor c in λ² = λ₀² + c |e|² (tuned on benchmarks/bench_ik.py).
_LM = 0.03
#: ε of the null-space projector J⁺ = Jᵀ (J Jᵀ + ε I)⁻¹.
_EPS = 1e-12
#: Random configurations drawn per restart; the one with the smallest |e|² is the new start.
_CANDIDATES = 8
_EYE = {m: np.eye(m) for m in range(1, 7)}
_EPS_EYE = {m: _EPS * np.eye(m) for m in range(1, 7)}


@dataclass(frozen=True)
class IKResult:
    """Outcome of :func:`generalized_ik`.

    ``theta`` the final joint angles (rad, length n, always within the limits); ``success`` whether the
    primary task converged there; ``iterations`` over all starts; ``residual`` |e| of the primary task
    (m; orientation rows weighted by the sphere radius); ``time_s`` wall time; ``message`` what
    happened; ``restarts`` random restarts used.
    """

    theta: Array
    success: bool
    iterations: int
    residual: float
    time_s: float
    message: str
    restarts: int = 0


def null_space_step(jacobian: Array, error: Array, gamma: Array | None, damping: float) -> Array:
    """δθ = J# e + (I − J⁺ J) γ: J# = Jᵀ (J Jᵀ + λ² I)⁻¹ the damped pseudoinverse (λ² = ``damping``),
    J⁺ = Jᵀ (J Jᵀ + ε I)⁻¹ with ε = 1e-12 (the null-space projector, exact up to ε).

    The projector is not damped, so the γ part moves θ in the null space of J (the primary task is
    unchanged to first order) however large λ is. ``gamma=None`` means γ = 0. Two m×m LAPACK solves
    (``gesv``: ~1 µs each where numpy's ``solve`` takes ~3 µs).
    """
    a = jacobian @ jacobian.T
    m = len(a)
    _, _, x, info = _gesv(a + damping * _EYE[m], error)
    if info != 0:
        x = _lstsq(a + damping * _EYE[m], error)
    if gamma is None:
        return cast(Array, jacobian.T @ x)
    jg = jacobian @ gamma
    _, _, y, info = _gesv(a + _EPS_EYE[m], jg)
    if info != 0:
        y = _lstsq(a + _EPS_EYE[m], jg)
    return cast(Array, gamma + jacobian.T @ (x - y))


def _lstsq(a: Array, b: Array) -> Array:
    """Least-squares a⁻¹ b where LAPACK found ``a`` singular (J without a usable column and λ = 0)."""
    return cast(Array, np.linalg.lstsq(a, b, rcond=None)[0])


def _limit_side(theta: Array, lower: Array, upper: Array) -> Array | None:
    """+1 where θ ≥ upper, −1 where θ ≤ lower, 0 elsewhere; None when no joint is at a limit."""
    side = cast(Array, (theta >= upper) * 1.0 - (theta <= lower))
    return side if side.any() else None


def _restart(robot: Robot, primary: PrimaryTask, rng: np.random.Generator, candidates: int) -> Array:
    """The best of ``candidates`` random configurations within the limits, by primary error |e|²."""
    best, best_e2 = robot.theta_ref, np.inf
    for theta in robot.random_configuration(rng, candidates):
        e, _ = primary.error_and_jacobian(KinematicState.compute(robot, theta))
        e2 = float(e @ e)
        if e2 < best_e2:
            best, best_e2 = theta, e2
    return best


def make_primary_task(
    sphere: LightSphere,
    target: ArrayLike,
    task: Literal["5d", "6d"] | PrimaryTask = "5d",
    rotation: ArrayLike | None = None,
) -> PrimaryTask:
    """The primary task from its name: "5d" (:class:`LightPointingTask`, roll free) or "6d"
    (:class:`LightPoseTask`, roll from ``rotation`` or the default aim rotation)."""
    if not isinstance(task, str):
        return task
    if task == "5d":
        return LightPointingTask(sphere, target)
    if task == "6d":
        return LightPoseTask(sphere, target, rotation)
    raise ValueError(f"unknown IK task {task!r}; expected '5d' or '6d'")


def make_secondary_tasks(
    secondary: Sequence[str | SecondaryTask], weights: Mapping[str, float] | None = None
) -> list[SecondaryTask]:
    """Secondary task objects from names (gains from ``weights``, else :data:`DEFAULT_GAINS`) or
    ready-made objects (kept as they are). A zero gain drops the task."""
    out: list[SecondaryTask] = []
    gains = {**DEFAULT_GAINS, **(weights or {})}
    for item in secondary:
        if isinstance(item, str):
            if item not in SECONDARY_TASKS:
                raise ValueError(f"unknown secondary task {item!r}; choose from {', '.join(SECONDARY_TASKS)}")
            obj: SecondaryTask = SECONDARY_TASKS[item](gains[item])
        else:
            obj = item
        if obj.weight != 0.0:
            out.append(obj)
    return out


def ik_settings(solver: SolverSpec) -> dict[str, Any]:
    """Keyword arguments of :func:`generalized_ik` from a problem's ``[solver]`` table."""
    weights = {
        "joint_limits": solver.ik_joint_limit_gain,
        "manipulability": solver.ik_manipulability_gain,
        "posture": solver.ik_posture_gain,
    }
    return {
        "secondary": tuple(name for name, k in weights.items() if k > 0),
        "weights": weights,
        "max_iter": solver.ik_max_iter,
        "tol": solver.ik_tol,
        "damping": solver.ik_damping,
        "max_step": solver.ik_max_step_rad,
    }


def generalized_ik(
    robot: Robot,
    sphere: LightSphere,
    target: ArrayLike,
    theta0: ArrayLike | None = None,
    *,
    task: Literal["5d", "6d"] | PrimaryTask = "5d",
    rotation: ArrayLike | None = None,
    secondary: Sequence[str | SecondaryTask] = ("joint_limits",),
    weights: Mapping[str, float] | None = None,
    max_iter: int = _SPEC.ik_max_iter,
    tol: float = _SPEC.ik_tol,
    damping: float = _SPEC.ik_damping,
    max_step: float = _SPEC.ik_max_step_rad,
    restarts: bool = True,
    patience: int = 4,
    seed: int = 0,
) -> IKResult:
    """Joint angles that put the light on ``target`` pointing at the sphere centre.

    ``target``: light position a* (3,) on the sphere (m) or (zenith, azimuth) (rad). ``task``: "5d"
    (position + optical axis, roll free), "6d" (also the roll: ``rotation`` R*, default the aim
    rotation of :class:`LightPoseTask`) or a task object. ``theta0``: start (default θ_ref).
    ``secondary``/``weights``: null-space objectives and their gains. ``tol``: on |e|² (m²).
    ``patience``: iterations without a 2 % decrease of |e|² before a restart (``restarts``) from the
    best of 8 seeded random configurations; pass ``restarts=False`` to stay near ``theta0`` (path
    following). An unreachable target gives ``success=False`` with the closest θ found (within the
    limits); :class:`UnreachableError` only for a target position that is not on the sphere.
    """
    t_start = time.perf_counter()
    primary = make_primary_task(sphere, target, task, rotation)
    objectives = make_secondary_tasks(secondary, weights)
    lower, upper = robot.lower, robot.upper
    start = robot.theta_ref if theta0 is None else np.asarray(theta0, float)
    theta = np.minimum(np.maximum(start, lower), upper)

    best_theta, best_e2 = theta, np.inf
    run_best, stall, n_restarts = np.inf, 0, 0
    rng: np.random.Generator | None = None
    side = _limit_side(theta, lower, upper)  # −1 / +1 where θ sits on its lower / upper limit
    iterations = 0
    for iterations in range(1, max_iter + 1):  # noqa: B007 - the count is reported
        state = KinematicState.compute(robot, theta)
        e, jac = primary.error_and_jacobian(state)
        e2 = float(e @ e)
        if e2 < best_e2:
            best_theta, best_e2 = theta, e2
            if e2 < tol:
                break
        if e2 < 0.98 * run_best:
            run_best, stall = e2, 0
        else:
            stall += 1
            if restarts and stall >= patience:
                rng = rng if rng is not None else np.random.default_rng(seed)
                theta, side = _restart(robot, primary, rng, _CANDIDATES), None
                run_best, stall, n_restarts = np.inf, 0, n_restarts + 1
                continue

        gamma = None
        for obj in objectives:
            g = -obj.weight * obj.gradient(robot, state)
            gamma = g if gamma is None else gamma + g
        lam2 = damping + _LM * e2
        step = null_space_step(jac, e, gamma, lam2)
        if side is not None:
            blocked = side * step > 0.0  # pushing outwards at a limit
            if blocked.any():
                jac = jac.copy()
                jac[:, blocked] = 0.0
                if gamma is not None:
                    gamma[blocked] = 0.0
                step = null_space_step(jac, e, gamma, lam2)
                step[blocked] = 0.0
        biggest = float(np.abs(step).max())
        if biggest > max_step:
            step *= max_step / biggest
        free = theta + step
        theta = np.minimum(np.maximum(free, lower), upper)
        side = _limit_side(free, lower, upper) if (theta != free).any() else None
    else:
        state = KinematicState.compute(robot, theta)
        e, _ = primary.error_and_jacobian(state)
        e2 = float(e @ e)
        if e2 < best_e2:
            best_theta, best_e2 = theta, e2

    converged = best_e2 < tol
    inside = robot.within_limits(best_theta, tol=0.0)
    success = converged and inside
    if success:
        message = f"converged in {iterations} iterations ({n_restarts} restarts)"
    elif not inside:
        message = "solution outside the joint limits"
    else:
        message = (
            f"no convergence in {max_iter} iterations ({n_restarts} restarts), |e| = {np.sqrt(best_e2):.2e}"
        )
    return IKResult(
        theta=np.array(best_theta),
        success=success,
        iterations=iterations,
        residual=float(np.sqrt(best_e2)),
        time_s=time.perf_counter() - t_start,
        message=message,
        restarts=n_restarts,
    )
