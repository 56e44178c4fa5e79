"""Robots by name (example-robot-data) or from a user URDF, in joint-angle coordinates.

A :class:`Robot` is a pinocchio model of the arm that carries the light, with

- the hand/gripper joints locked (``pin.buildReducedModel``), so every remaining joint moves the light;
- the base placement ``T_WB`` (``base_position_m``, ``base_rpy_deg``) folded into the model: every
  joint and frame attached to the universe is pre-multiplied by ``T_WB``, so pinocchio's ``oMi``,
  ``oMf`` and everything built from the model (the CasADi mirror, Jacobians, geometry) are in the
  world frame W;
- two frames added at the end of the model: ``flange`` = the robot's tool frame, rotated where needed
  so that its +z points out of the tool, and ``light`` = ``flange · T(light_offset_m, light_rpy_deg)``.
  The light emits along +z of ``light`` (docs/design.md §2).

**Joint coordinates.** The rest of optlight works with joint *angles* θ ∈ Rⁿ, n = ``model.nv``, one
per joint, in URDF joint order. Pinocchio stores a continuous joint (kinova joints 1, 4, 6) as
(cos θ, sin θ); :meth:`Robot.to_pin` / :meth:`Robot.from_pin` convert. Continuous joints get the limits
±2π in θ (two full turns of cable; a trajectory never needs more), every other joint its URDF limits.

The named robots, their frames and published limits are in :mod:`optlight.robot.catalogue`; a user
URDF's files are found as :mod:`optlight.robot.urdf` describes.

Kinova's and z1's tool frames point their +x out of the tool; their ``flange`` is rotated by
Ry(+90°) so that +z does. The panda fingers and the z1 gripper joint are locked (closed).
``robot.velocity_scale`` is *not* applied here (the timing applies it).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Literal

import coal
import numpy as np
import pinocchio as pin
from numpy.typing import ArrayLike, NDArray

from optlight.errors import ProblemError, RobotError
from optlight.robot.catalogue import (
    DEFAULT_JERK_RAMP_S,
    ROBOTS,
    SUPPORTED_ROBOTS,
    RobotInfo,
    example_robot_data_dir,
)
from optlight.robot.kinematics import (
    CONTINUOUS_JOINTS,
    PRISMATIC_JOINTS,
    REVOLUTE_JOINTS,
    symbolic_frame_pose,
)
from optlight.robot.urdf import first_error, quiet_stderr, unread_visual_meshes, urdf_package_dirs
from optlight.spec import Problem, RobotSpec

if TYPE_CHECKING:
    import casadi

Array = NDArray[np.float64]

#: Limits given to continuous joints, in θ (rad).
CONTINUOUS_LIMIT = 2 * np.pi

#: The light's constraints at a capture (docs/design.md §3): h1–h3 (on the sphere, its axis through
#: O) and the capture's zenith and azimuth. An arm with fewer joints meets them only by chance.
LIGHT_CONSTRAINTS = 5


def placement(position: ArrayLike, rpy_deg: ArrayLike) -> pin.SE3:
    """SE(3) from a position (m) and URDF roll-pitch-yaw (deg): R = Rz(yaw)·Ry(pitch)·Rx(roll)."""
    r, p, y = np.deg2rad(np.asarray(rpy_deg, float))
    return pin.SE3(pin.rpy.rpyToMatrix(r, p, y), np.asarray(position, float))


class JointCoordinates:
    """The map between joint angles θ (n = nv, URDF joint order) and pinocchio's q (nq).

    Revolute and prismatic joints: q = θ. Continuous joints: q = (cos θ, sin θ), θ = atan2(sin, cos).
    """

    def __init__(self, model: pin.Model) -> None:
        joints = sorted(model.joints[1:], key=lambda j: j.idx_v)
        self.nq, self.n = int(model.nq), int(model.nv)
        self.names: list[str] = [model.names[j.id] for j in joints]
        self.kinds: list[str] = [j.shortname() for j in joints]
        self.continuous = np.array([k in CONTINUOUS_JOINTS for k in self.kinds], bool)
        self.idx_q = np.array([j.idx_q for j in joints], int)
        self._v_angle = np.flatnonzero(~self.continuous)
        self._q_angle = self.idx_q[~self.continuous]
        self._v_cont = np.flatnonzero(self.continuous)
        self._q_cos = self.idx_q[self.continuous]
        self._q_sin = self._q_cos + 1
        self.identity = bool(not self.continuous.any() and np.array_equal(self.idx_q, np.arange(self.n)))

    def to_pin(self, theta: ArrayLike) -> Array:
        """Pinocchio configuration q (..., nq) from joint angles θ (..., n): continuous joints become
        (cos θ, sin θ), every other joint is copied."""
        theta = np.asarray(theta, float)
        if self.identity:
            return theta.copy()
        q = np.empty(theta.shape[:-1] + (self.nq,))
        q[..., self._q_angle] = theta[..., self._v_angle]
        c = theta[..., self._v_cont]
        q[..., self._q_cos] = np.cos(c)
        q[..., self._q_sin] = np.sin(c)
        return q

    def from_pin(self, q: ArrayLike) -> Array:
        """Joint angles θ (..., n) from a pinocchio configuration q (..., nq); a continuous joint's
        angle is atan2(sin, cos) ∈ (−π, π]."""
        q = np.asarray(q, float)
        if self.identity:
            return q.copy()
        theta = np.empty(q.shape[:-1] + (self.n,))
        theta[..., self._v_angle] = q[..., self._q_angle]
        theta[..., self._v_cont] = np.arctan2(q[..., self._q_sin], q[..., self._q_cos])
        return theta


class Robot:
    """The arm carrying the light, in joint-angle coordinates θ (see the module docstring).

    Attributes: ``name``; pinocchio ``model`` and its scratch ``data`` (used by the numeric methods);
    ``flange_frame_id``/``light_frame_id`` (frames ``flange``, ``light``); ``joint_names`` (URDF names,
    θ order); ``n``; ``lower``/``upper`` (rad or m), ``velocity_limit`` (rad/s or m/s),
    ``acceleration_limit`` (rad/s² or m/s²), ``jerk_limit`` (rad/s³ or m/s³), ``theta_ref``: arrays of
    length n; ``torque_limit`` (N·m or N, length n, or None where none are published) and
    ``torque_limit_source`` (where they come from, or why there are none). ``base_placement`` is
    T_WB. ``urdf_path``/``package_dirs``/``locked_joints`` rebuild geometry (:meth:`geometry_model`).
    """

    def __init__(
        self,
        name: str,
        model: pin.Model,
        *,
        theta_ref: ArrayLike | None,
        acceleration_limit: ArrayLike,
        jerk_limit: ArrayLike,
        base_placement: pin.SE3,
        velocity_limit: ArrayLike | None = None,
        urdf_path: Path,
        package_dirs: Sequence[Path],
        locked_joints: dict[str, float],
        torque_limit: ArrayLike | None = None,
        torque_limit_source: str = "no published torque limits",
    ) -> None:
        self.name = name
        self.model = model
        self.data = model.createData()
        self.base_placement = base_placement
        self.urdf_path = urdf_path
        self.package_dirs = list(package_dirs)
        self.locked_joints = dict(locked_joints)
        self.flange_frame_id = model.getFrameId("flange")
        self.light_frame_id = model.getFrameId("light")
        self.n = int(model.nv)
        coords = JointCoordinates(model)
        self.joint_names: list[str] = coords.names
        self.joint_kinds: list[str] = coords.kinds
        #: True when q = θ (no continuous joint): the hot paths skip the conversion.
        self.angles_are_q = coords.identity
        self.to_pin = coords.to_pin
        self.from_pin = coords.from_pin
        cont = coords.continuous
        angle_v, angle_q = np.flatnonzero(~cont), coords.idx_q[~cont]

        self.lower = np.full(self.n, -CONTINUOUS_LIMIT)
        self.upper = np.full(self.n, CONTINUOUS_LIMIT)
        self.lower[angle_v] = model.lowerPositionLimit[angle_q]
        self.upper[angle_v] = model.upperPositionLimit[angle_q]
        self.velocity_limit = np.array(model.velocityLimit, float).copy()
        if velocity_limit is not None:
            published = np.broadcast_to(np.asarray(velocity_limit, float), (self.n,))
            self.velocity_limit = np.minimum(self.velocity_limit, published)
        self.acceleration_limit = np.broadcast_to(np.asarray(acceleration_limit, float), (self.n,)).copy()
        self.jerk_limit = np.broadcast_to(np.asarray(jerk_limit, float), (self.n,)).copy()
        if theta_ref is None:
            ref = np.where(cont, 0.0, 0.5 * (self.lower + self.upper))
        else:
            ref = _wrap_into_limits(np.asarray(theta_ref, float), self.lower, self.upper)
        self.theta_ref = ref
        self.torque_limit: Array | None = None
        if torque_limit is not None:
            self.torque_limit = np.broadcast_to(np.asarray(torque_limit, float), (self.n,)).copy()
            self.torque_limit.setflags(write=False)
        self.torque_limit_source = torque_limit_source
        #: The SRDF's named configurations (group states), as joint angles θ; filled by load_robot.
        self.named_configurations: dict[str, Array] = {}
        limits = (self.velocity_limit, self.acceleration_limit, self.jerk_limit)
        for arr in (self.lower, self.upper, *limits, self.theta_ref):
            arr.setflags(write=False)
        self._symbolic: casadi.Function | None = None

    def __repr__(self) -> str:
        tool = self.model.frames[self.model.frames[self.flange_frame_id].parentFrame].name
        return f"Robot({self.name!r}, n={self.n}, flange at {tool!r})"

    # ---------------------------------------------------------------- coordinates
    def within_limits(self, theta: ArrayLike, tol: float = 1e-9) -> bool:
        """Whether lower − tol ≤ θ ≤ upper + tol for every joint."""
        theta = np.asarray(theta, float)
        return bool((theta >= self.lower - tol).all() and (theta <= self.upper + tol).all())

    def random_configuration(self, rng: np.random.Generator, size: int | None = None) -> Array:
        """Joint angles drawn uniformly within the limits; shape (n,) or (size, n)."""
        shape = (self.n,) if size is None else (size, self.n)
        return rng.uniform(self.lower, self.upper, size=shape)

    # ---------------------------------------------------------------- numeric kinematics
    def light_pose(self, theta: ArrayLike) -> tuple[Array, Array]:
        """Light position a_L (3,) in m and rotation R_WL (3, 3) in the world frame (pinocchio)."""
        pin.forwardKinematics(self.model, self.data, self.to_pin(theta))
        m = pin.updateFramePlacement(self.model, self.data, self.light_frame_id)
        return m.translation.copy(), m.rotation.copy()

    def light_positions(self, thetas: ArrayLike) -> Array:
        """Light positions (K, 3) in m, world frame, at the joint angles ``thetas`` (K, n)."""
        return np.array([self.light_pose(theta)[0] for theta in np.reshape(thetas, (-1, self.n))])

    def frame_pose(self, frame: str, theta: ArrayLike) -> pin.SE3:
        """World placement of a frame of the model (any URDF link, ``flange`` or ``light``)."""
        fid = self.frame_id(frame)
        pin.forwardKinematics(self.model, self.data, self.to_pin(theta))
        return pin.updateFramePlacement(self.model, self.data, fid).copy()

    def light_jacobian(self, theta: ArrayLike) -> Array:
        """Light-frame Jacobian (6, n) in LOCAL_WORLD_ALIGNED: rows 0–2 the velocity of the light's
        origin (m/s), rows 3–5 its angular velocity (rad/s), both in world axes, per unit θ̇."""
        pin.computeJointJacobians(self.model, self.data, self.to_pin(theta))
        return pin.getFrameJacobian(self.model, self.data, self.light_frame_id, pin.LOCAL_WORLD_ALIGNED)

    def frame_id(self, frame: str) -> int:
        """Index of a frame by name; :class:`RobotError` lists the frames when it does not exist."""
        return _find_frame(self.model, frame, self.name)

    # ---------------------------------------------------------------- symbolic kinematics
    @property
    def symbolic_light_pose(self) -> casadi.Function:
        """CasADi ``light_pose``: θ (n×1) → (a_L (3×1), R_WL (3×3)); built once, then cached."""
        if self._symbolic is None:
            self._symbolic = symbolic_frame_pose(self.model, self.light_frame_id, name="light_pose")
        return self._symbolic

    # ---------------------------------------------------------------- geometry
    def geometry_model(
        self, kind: Literal["collision", "visual"] = "collision", *, read_meshes: bool = False
    ) -> pin.GeometryModel:
        """Collision or visual geometry of the robot, consistent with :attr:`model`: locked joints
        reduced away, base placement applied.

        Collision meshes are read from the URDF's packages (distances are taken on them). Visual
        meshes are only drawn, by the preview, which reads each file itself
        (:mod:`optlight.viz.meshes`): by default they are not read (:func:`unread_visual_meshes`;
        reading the Panda's COLLADA files into coal costs 0.18 s, for nothing). ``read_meshes=True``
        reads them too, into axis-aligned bounding-box trees (less than half the time of the
        default OBBRSS trees), as the check of a user URDF does."""
        gtype = pin.GeometryType.COLLISION if kind == "collision" else pin.GeometryType.VISUAL
        dirs = [str(p) for p in self.package_dirs]
        with quiet_stderr() as said:
            try:
                full = pin.buildModelFromUrdf(str(self.urdf_path))
                if kind == "collision":
                    geom = pin.buildGeomFromUrdf(full, str(self.urdf_path), gtype, package_dirs=dirs)
                elif read_meshes:
                    loader = coal.MeshLoader(coal.BV_AABB)
                    geom = pin.buildGeomFromUrdf(full, str(self.urdf_path), gtype, package_dirs=dirs, mesh_loader=loader)
                else:
                    geom = unread_visual_meshes(full, self.urdf_path)
            except (RuntimeError, ValueError) as e:
                detail = first_error(said, e)
                raise RobotError(
                    f"{self.name}: cannot read the {kind} meshes of {self.urdf_path}: {detail}"
                ) from None
        if self.locked_joints:
            ids = [full.getJointId(j) for j in self.locked_joints]
            q = pin.neutral(full)
            for j, value in self.locked_joints.items():
                q[full.joints[full.getJointId(j)].idx_q] = value
            _, geom = pin.buildReducedModel(full, geom, ids, q)
        for obj in geom.geometryObjects:
            if obj.parentJoint == 0:
                obj.placement = self.base_placement * obj.placement
        return geom


def _torque_limit(info: RobotInfo, model: pin.Model, urdf: Path) -> tuple[Array | None, str]:
    """The joint torque limits (N·m) of the (reduced) model and where they come from: the maker's
    published ones (``info.torque_limit``), else the URDF's effort limits when every joint has one
    (> 0), else None."""
    if info.torque_limit is not None:
        limit = np.asarray(info.torque_limit, float)
        if limit.shape != (model.nv,):
            raise RobotError(f"{urdf.name}: {limit.size} torque limits for {model.nv} joints")
        return limit, info.torque_source
    effort = np.array([model.effortLimit[j.idx_v] for j in model.joints[1:]], float)
    if effort.size == model.nv and np.all(np.isfinite(effort)) and np.all(effort > 0):
        return effort, f"the effort limits of {urdf.name}"
    return None, f"no published torque limits ({urdf.name} has no effort limits)"


def _wrap_into_limits(theta: Array, lower: Array, upper: Array) -> Array:
    """θ with each value outside [lower, upper] moved by a multiple of 2π inside when possible."""
    out = theta.copy()
    for i, (t, lo, hi) in enumerate(zip(theta, lower, upper, strict=True)):
        if lo <= t <= hi:
            continue
        k = np.ceil((lo - t) / (2 * np.pi))
        if lo <= t + 2 * np.pi * k <= hi:
            out[i] = t + 2 * np.pi * k
        else:
            out[i] = min(max(t, lo), hi)
    return out


def _find_frame(model: pin.Model, name: str, robot: str) -> int:
    """A frame by name, preferring OP_FRAME, BODY, FIXED_JOINT, JOINT when several share it."""
    for ftype in (pin.FrameType.OP_FRAME, pin.FrameType.BODY, pin.FrameType.FIXED_JOINT, pin.FrameType.JOINT):
        if model.existFrame(name, ftype):
            return int(model.getFrameId(name, ftype))
    raise RobotError(f"{robot}: no frame {name!r}; available frames: {', '.join(_frame_names(model))}")


def _frame_names(model: pin.Model) -> list[str]:
    return sorted({f.name for f in model.frames if f.type != pin.FrameType.JOINT})


def load_robot(source: Problem | RobotSpec | str) -> Robot:
    """The robot of a problem, a ``[robot]`` spec, or a robot name from :data:`SUPPORTED_ROBOTS`.

    A relative ``urdf`` path is resolved against the problem file (``Problem``) or the working
    directory (``RobotSpec``). Raises :class:`RobotError` for an unknown robot, a missing file or an
    unsupported joint type, listing what is available; from a ``Problem``, a user URDF that does not
    parse, whose meshes do not resolve or that has fewer joints than the light's
    :data:`LIGHT_CONSTRAINTS` (the problem's robot is to be planned; a spec's may have fewer, for its
    kinematics alone), and an unknown frame, are :class:`ProblemError` naming ``robot.urdf`` and
    ``robot.frame`` (from a spec or name, RobotError naming the key).
    """
    spec, urdf, file = _robot_source(source)
    files = _robot_files(spec, urdf, file)
    full = _read_urdf(files.urdf_path, spec, urdf, file)
    q_full, states = _reference_configuration(full, files, spec)
    locked = _locked_joints(full, files, spec, q_full)
    model = _reduced_model(full, locked, q_full, spec)
    base = placement(spec.base_position_m, spec.base_rpy_deg)
    _place_base(model, base)
    _add_light_frames(model, spec, files, file)
    theta_ref = _theta_ref(files.info, spec, full, model, locked, q_full)
    limits = _acceleration_and_jerk(spec, files.info, model.nv)
    torque, torque_source = _torque_limit(files.info, model, files.urdf_path)
    robot = Robot(
        spec.name,
        model,
        theta_ref=theta_ref,
        acceleration_limit=limits["acceleration_limit"],
        jerk_limit=limits["jerk_limit"],
        velocity_limit=files.info.velocity_limit,
        base_placement=base,
        urdf_path=files.urdf_path,
        package_dirs=files.package_dirs,
        locked_joints=locked,
        torque_limit=torque,
        torque_limit_source=torque_source,
    )
    robot.named_configurations = {
        name: _wrap_into_limits(_reduced_angles(full, model, locked, q), robot.lower, robot.upper)
        for name, q in states.items()
    }
    return robot


@dataclass(frozen=True)
class _RobotFiles:
    """A robot's catalogue entry (or one made for a user URDF), its URDF and SRDF and the folders its
    ``package://`` meshes are found in."""

    info: RobotInfo
    urdf_path: Path
    srdf_path: Path | None
    package_dirs: list[Path]


def _robot_source(source: Problem | RobotSpec | str) -> tuple[RobotSpec, Path | None, str | None]:
    """The robot spec, its user URDF resolved (or None for a named robot) and the problem file to name
    in errors (None outside a problem)."""
    if isinstance(source, Problem):
        spec = source.robot
        urdf = source.resolve(spec.urdf) if spec.urdf is not None else None
        return spec, urdf, str(source.source) if source.source else "<inline>"
    if isinstance(source, RobotSpec):
        return source, Path(source.urdf).expanduser().resolve() if source.urdf is not None else None, None
    return RobotSpec(name=source), None, None


def _robot_files(spec: RobotSpec, urdf: Path | None, file: str | None) -> _RobotFiles:
    """The files of a user URDF (every mesh checked to resolve) or of a named robot."""
    if urdf is not None:
        if not urdf.is_file():
            raise RobotError(f"robot.urdf: no file {urdf}")
        if spec.frame is None:
            raise RobotError("robot.frame: a user URDF needs the name of its flange frame")
        info = RobotInfo(str(urdf), None, spec.frame)
        return _RobotFiles(info, urdf, None, urdf_package_dirs(urdf, file or str(urdf)))
    if spec.name not in ROBOTS:
        raise RobotError(
            f"unknown robot {spec.name!r}; supported robots: {', '.join(SUPPORTED_ROBOTS)} "
            "(or set robot.urdf and robot.frame)"
        )
    info = ROBOTS[spec.name]
    share = example_robot_data_dir()
    robots = share / "example-robot-data" / "robots"
    return _RobotFiles(info, robots / info.urdf, robots / info.srdf if info.srdf else None, [share])


def _read_urdf(urdf_path: Path, spec: RobotSpec, urdf: Path | None, file: str | None) -> pin.Model:
    """The full pinocchio model of the URDF, the parser's messages kept out of the terminal."""
    with quiet_stderr() as said:
        try:
            return pin.buildModelFromUrdf(str(urdf_path))
        except (RuntimeError, ValueError) as e:
            if urdf is not None and file is not None:
                raise ProblemError(
                    file, "robot.urdf", f"a URDF pinocchio reads ({first_error(said, e)})", spec.urdf
                ) from None
            raise RobotError(f"{spec.name}: cannot read {urdf_path}: {first_error(said, e)}") from None


def _reference_configuration(
    full: pin.Model, files: _RobotFiles, spec: RobotSpec
) -> tuple[Array, dict[str, Array]]:
    """The full model's reference configuration (the catalogue's SRDF state, else neutral) and every
    SRDF state by name."""
    q_full = pin.neutral(full)
    states: dict[str, Array] = {}
    if files.srdf_path is not None:
        pin.loadReferenceConfigurations(full, str(files.srdf_path))
        states = {e.key(): np.array(e.data()) for e in full.referenceConfigurations}
    reference = files.info.reference
    if reference is not None:
        if reference not in states:
            raise RobotError(f"{spec.name}: no reference configuration {reference!r} in {files.srdf_path}")
        q_full = states[reference]
    return q_full, states


def _locked_joints(full: pin.Model, files: _RobotFiles, spec: RobotSpec, q_full: Array) -> dict[str, float]:
    """The hand joints to lock, each at 0 (set so in ``q_full``)."""
    missing = [j for j in files.info.locked_joints if not full.existJointName(j)]
    if missing:
        raise RobotError(f"{spec.name}: no joint {missing[0]!r} to lock in {files.urdf_path}")
    locked = dict.fromkeys(files.info.locked_joints, 0.0)
    for j in locked:
        q_full[full.joints[full.getJointId(j)].idx_q] = 0.0
    return locked


def _reduced_model(full: pin.Model, locked: dict[str, float], q_full: Array, spec: RobotSpec) -> pin.Model:
    """The model with the locked joints reduced away; RobotError for a joint type optlight does not
    handle."""
    model = (
        pin.buildReducedModel(full, [full.getJointId(j) for j in locked], q_full) if locked else full.copy()
    )
    bad = [
        f"{model.names[j.id]} ({j.shortname()})"
        for j in model.joints[1:]
        if j.shortname() not in REVOLUTE_JOINTS | PRISMATIC_JOINTS | CONTINUOUS_JOINTS
    ]
    if bad:
        raise RobotError(
            f"{spec.name}: unsupported joint types {', '.join(bad)}; optlight handles revolute, "
            "continuous and prismatic joints"
        )
    return model


def _place_base(model: pin.Model, base: pin.SE3) -> None:
    """Fold the base placement T_WB into the model: every joint and frame attached to the universe is
    pre-multiplied by it."""
    for jid in range(1, model.njoints):
        if model.parents[jid] == 0:
            model.jointPlacements[jid] = base * model.jointPlacements[jid]
    for f in range(1, model.nframes):
        if model.frames[f].parentJoint == 0:
            model.frames[f].placement = base * model.frames[f].placement


def _add_light_frames(model: pin.Model, spec: RobotSpec, files: _RobotFiles, file: str | None) -> None:
    """Add ``flange`` (the tool frame with +z out of the tool) and ``light`` = flange ·
    T(light_offset_m, light_rpy_deg), after checking the tool frame and (a problem's robot, to be
    planned) that the arm has at least :data:`LIGHT_CONSTRAINTS` joints."""
    frame_name = spec.frame if spec.frame is not None else files.info.tool_frame
    if not model.existFrame(frame_name):
        expected = f"a frame of {spec.name} ({', '.join(_frame_names(model))})"
        if file is not None:
            raise ProblemError(file, "robot.frame", expected, frame_name)
        raise RobotError(f"robot.frame: expected {expected}, got {frame_name!r}")
    if file is not None and model.nv < LIGHT_CONSTRAINTS:  # a problem's robot is to be planned
        joints = ", ".join(model.names[j.id] for j in model.joints[1:])
        raise ProblemError(
            file,
            "robot.urdf",
            f"an arm with at least {LIGHT_CONSTRAINTS} joints for the light's {LIGHT_CONSTRAINTS} constraints "
            f"(h1–h3, zenith, azimuth); {files.urdf_path.name} has {model.nv} ({joints})",
        )
    tool = model.frames[_find_frame(model, frame_name, spec.name)]
    for taken in ("flange", "light"):
        if model.existFrame(taken):
            raise RobotError(
                f"{spec.name}: the URDF already has a frame named {taken!r}, which optlight adds"
            )
    fix = placement((0, 0, 0), files.info.tool_rpy_deg if spec.frame is None else (0, 0, 0))
    if spec.frame is None:  # the named robot's flange, past its gripper (RobotInfo.tool_offset_m)
        fix = fix * pin.SE3(np.eye(3), np.array([0.0, 0.0, files.info.tool_offset_m]))
    flange_id = model.addFrame(
        pin.Frame(
            "flange",
            tool.parentJoint,
            _find_frame(model, frame_name, spec.name),
            tool.placement * fix,
            pin.FrameType.OP_FRAME,
        )
    )
    offset = placement(spec.light_offset_m, spec.light_rpy_deg)
    model.addFrame(
        pin.Frame(
            "light",
            tool.parentJoint,
            flange_id,
            model.frames[flange_id].placement * offset,
            pin.FrameType.OP_FRAME,
        )
    )


def _reduced_angles(full: pin.Model, model: pin.Model, locked: dict[str, float], q: Array) -> Array:
    """θ of the reduced model from a configuration q of the full one."""
    kept = [q[j.idx_q : j.idx_q + j.nq] for j in full.joints[1:] if full.names[j.id] not in locked]
    return JointCoordinates(model).from_pin(np.concatenate(kept))


def _theta_ref(
    info: RobotInfo, spec: RobotSpec, full: pin.Model, model: pin.Model, locked: dict[str, float], q_full: Array
) -> Array | None:
    """θ_ref: the SRDF state (reduced), the catalogue's default, or None (a user URDF: :class:`Robot`
    takes the limits' middle)."""
    if info.reference is not None:
        return _reduced_angles(full, model, locked, q_full)
    if info.theta_ref is None:
        return None
    theta_ref = np.asarray(info.theta_ref, float)
    if theta_ref.shape != (model.nv,):
        raise RobotError(f"{spec.name}: reference has {theta_ref.size} values for {model.nv} joints")
    return theta_ref


def _acceleration_and_jerk(spec: RobotSpec, info: RobotInfo, n: int) -> dict[str, Array | float]:
    """``acceleration_limit`` and ``jerk_limit``: the spec's overrides, else the catalogue's (a jerk
    not published is the :data:`DEFAULT_JERK_RAMP_S` ramp of the acceleration in use); one value or
    one per joint (RobotError otherwise)."""
    accel = spec.acceleration_limit if spec.acceleration_limit is not None else info.acceleration_limit
    jerk = spec.jerk_limit if spec.jerk_limit is not None else info.jerk()
    if spec.jerk_limit is None and spec.acceleration_limit is not None and info.jerk_limit is None:
        jerk = tuple(np.asarray(accel, float).ravel() / DEFAULT_JERK_RAMP_S)  # the ramp of the override
    limits: dict[str, Array | float] = {}
    for name, value in (("acceleration_limit", accel), ("jerk_limit", jerk)):
        arr = np.asarray(value, float)
        if arr.ndim and arr.shape not in ((1,), (n,)):
            raise RobotError(f"robot.{name}: {arr.size} values for the {n} joints of {spec.name}")
        limits[name] = arr.ravel() if arr.shape != (1,) else arr[0]
    return limits
