"""IK tasks: primary light tasks (error, Jacobian) and secondary objectives H(θ) (gradient).

Everything works from one :class:`KinematicState` (pinocchio's forward kinematics and frame Jacobian
of the light at θ, computed once per iteration), in the style of pink's ``Configuration``.

Primary tasks give an error e (what is left to close) and a Jacobian J with J δθ ≈ e to first order:

- :class:`LightPointingTask` (5-D): light position a_L on the target a* (3 rows, m) and optical axis
  z_L through the sphere centre O (2 rows); the roll about z_L is free.
- :class:`LightPoseTask` (6-D): position and full orientation R* (3 + 3 rows).

Errors and Jacobians are written in the light frame L (pinocchio's LOCAL Jacobian): rotating the rows
by R_WLᵀ changes neither the least-squares step nor |e|. Orientation rows are rotation vectors (rad)
multiplied by a length w (default: the sphere radius b), so they read as metres: w·angle is how far
the optical axis misses O.

Secondary objectives H(θ) are minimised in the null space of the primary task (γ = −k ∇H):
:class:`JointLimitTask`, :class:`ManipulabilityTask`, :class:`PostureTask`.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np
import pinocchio as pin
from numpy.typing import ArrayLike, NDArray

from optlight.errors import UnreachableError
from optlight.geometry import LightSphere

if TYPE_CHECKING:
    from optlight.robot.loading import Robot

Array = NDArray[np.float64]

_LOCAL = pin.ReferenceFrame.LOCAL


class KinematicState:
    """Light pose and Jacobian at θ: ``position`` a_L (3,) m, ``rotation`` R_WL (3, 3) and
    ``local_jacobian`` (6, n), pinocchio's LOCAL frame Jacobian of the light (the twist of the light
    frame in its own axes: rows 0–2 Rᵀ·(velocity of a_L), rows 3–4 Rᵀ·ω). ``jacobian`` is the
    LOCAL_WORLD_ALIGNED one (world axes), made from it on first use.

    Holding one means the kinematics is up to date (built by :meth:`compute`, one pinocchio pass).
    """

    __slots__ = ("_jacobian", "local_jacobian", "position", "rotation", "theta")

    def __init__(self, theta: Array, position: Array, rotation: Array, local_jacobian: Array) -> None:
        self.theta = theta
        self.position = position
        self.rotation = rotation
        self.local_jacobian = local_jacobian
        self._jacobian: Array | None = None

    @classmethod
    def compute(cls, robot: Robot, theta: Array) -> KinematicState:
        """Forward kinematics and the light Jacobian at θ."""
        q = theta if robot.angles_are_q else robot.to_pin(theta)
        pin.computeJointJacobians(robot.model, robot.data, q)
        m = pin.updateFramePlacement(robot.model, robot.data, robot.light_frame_id)
        local = pin.getFrameJacobian(robot.model, robot.data, robot.light_frame_id, _LOCAL)
        return cls(theta, m.translation, m.rotation, local)  # pinocchio returns copies: safe to keep

    @property
    def jacobian(self) -> Array:
        """LOCAL_WORLD_ALIGNED Jacobian (6, n): [R J_local,v ; R J_local,ω]."""
        if self._jacobian is None:
            r, local = self.rotation, self.local_jacobian
            self._jacobian = np.concatenate((r @ local[:3], r @ local[3:]))
        return self._jacobian


class PrimaryTask(Protocol):
    """A task the IK drives to zero: ``error_and_jacobian(state) -> (e (m,), J (m, n))``."""

    dim: int

    def error_and_jacobian(self, state: KinematicState) -> tuple[Array, Array]: ...


def _target_position(sphere: LightSphere, target: ArrayLike, tol: float = 1e-6) -> Array:
    """a* from a light position (3,) on the sphere or from (zenith, azimuth) in rad."""
    t = np.asarray(target, float)
    if t.shape == (2,):
        return np.asarray(sphere.position(t[0], t[1]), float)
    if t.shape != (3,):
        raise UnreachableError(f"IK target must be a position (3,) or (zenith, azimuth), got shape {t.shape}")
    off = abs(float(np.linalg.norm(t - sphere.center)) - sphere.radius)
    if off > tol:
        raise UnreachableError(
            f"IK target {t.round(4).tolist()} is {off:.2e} m off the light sphere "
            f"(centre {sphere.center.round(4).tolist()}, radius {sphere.radius:g} m)"
        )
    return t


class LightPointingTask:
    """5-D task: a_L = a* and z_L ∥ d* = (O − a*)/b, roll free.

    In the light frame: e = [R_WLᵀ (a* − a_L) ; w·(φ_x, φ_y)], where φ is the rotation vector that
    turns z_L onto d*: with d = R_WLᵀ d*, φ = atan2(|(d_x, d_y)|, d_z) · (−d_y, d_x, 0)/|(d_x, d_y)|.
    J = rows 0–4 of the LOCAL Jacobian, rows 3–4 times w (exact at e = 0, first-order near it:
    Gauss–Newton keeps its quadratic convergence). φ has no spurious zero at z_L = −d* (angle π),
    unlike z_L × d*.
    """

    dim = 5

    def __init__(self, sphere: LightSphere, target: ArrayLike, *, orientation_weight: float | None = None):
        self.sphere = sphere
        self.target = _target_position(sphere, target)
        axis = sphere.center - self.target
        self.axis = axis / np.linalg.norm(axis)
        self.weight = float(sphere.radius if orientation_weight is None else orientation_weight)
        self._rows = np.array([1.0, 1.0, 1.0, self.weight, self.weight])[:, None]
        self._vectors = np.array([self.target, self.axis])  # row 0 becomes a* − a_L below

    def error_and_jacobian(self, state: KinematicState) -> tuple[Array, Array]:
        """(e (5,), J (5, n)) at ``state``: position error in m, pointing error in weighted rad."""
        vectors = self._vectors
        np.subtract(self.target, state.position, out=vectors[0])
        (px, py, pz), (dx, dy, dz) = (vectors @ state.rotation).tolist()  # R_WLᵀ (a* − a_L), R_WLᵀ d*
        s = math.hypot(dx, dy)
        k = self.weight * (math.atan2(s, dz) / s if s > 1e-12 else 1.0)
        return np.array([px, py, pz, -k * dy, k * dx]), self._rows * state.local_jacobian[:5]


class LightPoseTask:
    """6-D task: a_L = a*, R_WL = R* (roll fixed). In the light frame e = [R_WLᵀ (a* − a_L) ;
    w·log3(R_WLᵀ R*)], J = the LOCAL Jacobian with rows 3–5 times w (the Jacobian of log3 is taken
    as identity: Gauss–Newton, exact at e = 0).

    R* must point its z axis at O; by default it is ``aim_rotation(a*, O, x_S)`` (the roll that keeps
    x_L along the sphere's x axis), see :func:`optlight.geometry.aim_rotation`.
    """

    dim = 6

    def __init__(
        self,
        sphere: LightSphere,
        target: ArrayLike,
        rotation: ArrayLike | None = None,
        *,
        orientation_weight: float | None = None,
    ) -> None:
        from optlight.geometry import aim_rotation

        self.sphere = sphere
        self.target = _target_position(sphere, target)
        axis = (sphere.center - self.target) / np.linalg.norm(sphere.center - self.target)
        if rotation is None:
            reference = sphere.rotation[:, 0]
            if abs(reference @ axis) > 0.99:
                reference = sphere.rotation[:, 1]
            self.rotation = aim_rotation(self.target, sphere.center, reference)
        else:
            self.rotation = np.asarray(rotation, float)
            miss = float(np.linalg.norm(self.rotation[:, 2] - axis))
            if miss > 1e-6:
                raise UnreachableError(
                    f"IK target rotation: its z axis misses the sphere centre by {miss:.2e}"
                )
        self.weight = float(sphere.radius if orientation_weight is None else orientation_weight)

    def error_and_jacobian(self, state: KinematicState) -> tuple[Array, Array]:
        """(e (6,), J (6, n)) at ``state``."""
        e = np.concatenate(
            (self.target - state.position, self.weight * pin.log3(state.rotation.T @ self.rotation))
        )
        return e, np.concatenate((state.jacobian[:3], self.weight * state.local_jacobian[3:]))


# ------------------------------------------------------------------------------------------------
# Secondary objectives
# ------------------------------------------------------------------------------------------------


class SecondaryTask(Protocol):
    """An objective H(θ) minimised in the null space: ``value`` and ``gradient`` (n,), gain ``weight``."""

    name: str
    weight: float

    def value(self, robot: Robot, state: KinematicState) -> float: ...

    def gradient(self, robot: Robot, state: KinematicState) -> Array: ...


class JointLimitTask:
    """Joint-limit avoidance (Liégeois): H = ½ Σ_i ((θ_i − c_i)/(u_i − l_i))², c = (l + u)/2.

    ∇H_i = (θ_i − c_i)/(u_i − l_i)²: moves every joint towards the middle of its range, in
    proportion to how far out it is relative to the range (dimensionless H).
    """

    name = "joint_limits"

    def __init__(self, weight: float = 1.0) -> None:
        self.weight = float(weight)
        self._limits: tuple[Array, Array] | None = None
        self._centre = self._scale = np.zeros(0)

    def value(self, robot: Robot, state: KinematicState) -> float:
        """H(θ) (dimensionless)."""
        x = (state.theta - 0.5 * (robot.lower + robot.upper)) / (robot.upper - robot.lower)
        return 0.5 * float(x @ x)

    def gradient(self, robot: Robot, state: KinematicState) -> Array:
        """∇H (n,), 1/rad."""
        limits = self._limits
        if limits is None or limits[0] is not robot.lower or limits[1] is not robot.upper:
            self._limits = (robot.lower, robot.upper)
            self._centre = 0.5 * (robot.lower + robot.upper)
            self._scale = 1.0 / (robot.upper - robot.lower) ** 2
        return (state.theta - self._centre) * self._scale


class PostureTask:
    """Posture: H = ½ |θ − θ_ref|², ∇H = θ − θ_ref (rad). θ_ref defaults to the robot's."""

    name = "posture"

    def __init__(self, weight: float = 1.0, theta_ref: ArrayLike | None = None) -> None:
        self.weight = float(weight)
        self.theta_ref = None if theta_ref is None else np.asarray(theta_ref, float)

    def _ref(self, robot: Robot) -> Array:
        return robot.theta_ref if self.theta_ref is None else self.theta_ref

    def value(self, robot: Robot, state: KinematicState) -> float:
        """H(θ) in rad²."""
        d = state.theta - self._ref(robot)
        return 0.5 * float(d @ d)

    def gradient(self, robot: Robot, state: KinematicState) -> Array:
        """∇H (n,), rad."""
        return state.theta - self._ref(robot)


def manipulability(jacobian: Array) -> float:
    """Yoshikawa's manipulability w = sqrt(det(J Jᵀ)) of a (6, n) Jacobian (0 at singularities)."""
    return math.sqrt(max(float(np.linalg.det(jacobian @ jacobian.T)), 0.0))


def _cross(a: NDArray[Any], b: NDArray[Any]) -> Array:
    """Column-wise cross product of two (3, n) arrays (np.cross is slow on small arrays)."""
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])


class ManipulabilityTask:
    """Manipulability: H = −log w, w = sqrt(det(J Jᵀ)), J the (6, n) LOCAL_WORLD_ALIGNED light Jacobian.

    Analytic gradient for a serial chain with columns (v_j, ω_j): ∂v_j/∂θ_k = ω_k × v_j and
    ∂ω_j/∂θ_k = ω_k × ω_j for k < j, ∂v_j/∂θ_k = ω_j × v_k and ∂ω_j/∂θ_k = 0 for k ≥ j. With
    M = (J Jᵀ)⁻¹ J, ∂ log w/∂θ_k = ⟨∂J/∂θ_k, M⟩ = ω_k · Σ_{j>k} (v_j × M_v,j + ω_j × M_ω,j)
    + v_k · Σ_{j≤k} (M_v,j × ω_j), O(n). H is scale-free; it grows without bound at singularities.
    """

    name = "manipulability"

    def __init__(self, weight: float = 1.0) -> None:
        self.weight = float(weight)

    def value(self, robot: Robot, state: KinematicState) -> float:
        """H(θ) = −log w."""
        return -math.log(max(manipulability(state.jacobian), 1e-300))

    def gradient(self, robot: Robot, state: KinematicState) -> Array:
        """∇H = −∇ log w (n,), 1/rad."""
        jac = state.jacobian
        m = np.linalg.solve(jac @ jac.T, jac)
        v, w = jac[:3], jac[3:]
        a = _cross(v, m[:3]) + _cross(w, m[3:])
        b = _cross(m[:3], w)
        after = np.cumsum(a[:, ::-1], axis=1)[:, ::-1] - a  # Σ_{j>k} A_j
        upto = np.cumsum(b, axis=1)  # Σ_{j≤k} B_j
        return -(np.einsum("ik,ik->k", w, after) + np.einsum("ik,ik->k", v, upto))


SECONDARY_TASKS: dict[str, type[JointLimitTask] | type[PostureTask] | type[ManipulabilityTask]] = {
    "joint_limits": JointLimitTask,
    "posture": PostureTask,
    "manipulability": ManipulabilityTask,
}
