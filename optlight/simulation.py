"""Execution of a results folder in a physics engine (MuJoCo, the optional extra ``optlight[sim]``).

``optlight simulate RESULTS_DIR`` runs the motion a controller would be given, joint_trajectory.yaml's
waypoints interpolated quintically (as ROS 2's joint_trajectory_controller interpolates them), through
a computed-torque joint controller on a MuJoCo model of the arm and the lamp, and reports what a real
run would show first: how closely the joints follow, where the light is when the camera triggers
(captures.csv's ``trigger_s``), and the torques the motors give.

**Model** (:func:`mjcf_of`). The MJCF is written from the plan's pinocchio model
(:class:`optlight.robot.Dynamics`: the URDF's kinematic tree and inertias, the hand joints locked, the
base placement applied, the lamp's mass and centre of mass added to the flange's body): one MuJoCo
body per joint at the joint's placement in its parent, a hinge (revolute, continuous) or slide
(prismatic) joint on the joint's axis, the body's inertia at its centre of mass, a ``light`` site at
the light frame, and a motor per joint whose force is clipped to the robot's torque limit (none
where it has no published limits). The model has no geometry: nothing collides (the plan's
clearances are verified by exact distances), and the meshes add nothing to the dynamics, so none
are loaded or converted. No joint friction, damping or rotor inertia (the URDFs hold none).
Gravity −9.81 m/s² along the world's z, RK4 integration at :data:`SUBSTEPS` steps per control period.

**Controller.** At the controller rate f (``[trajectory] rate_hz``), from the measured (q, q̇) and the
reference (q_r, q̇_r, q̈_r) at t_k = k/f, the torque held until t_{k+1} is

    τ = M(q) (q̈_r + K_p (q_r − q) + K_d (q̇_r − q̇)) + b(q, q̇),   K_p = ω², K_d = 2ω,

with M and the bias forces b (Coriolis, centrifugal, gravity) MuJoCo's own (``mj_inverse``), ω = 2π · :data:`BANDWIDTH_HZ`
(critically damped), clipped to the torque limits. The simulation starts at rest at the first
waypoint and steps exactly onto each trigger time to read the light's pose there.
"""

from __future__ import annotations

import csv
import json
import math
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any
from xml.sax.saxutils import quoteattr

import numpy as np
import pinocchio as pin
from numpy.typing import NDArray

from optlight.errors import OptlightError, UsageError
from optlight.export import read_joint_trajectory
from optlight.jsondata import json_safe
from optlight.motion import Trajectory
from optlight.robot import Dynamics, load_robot
from optlight.robot.kinematics import joint_axis
from optlight.setup import lamp_of
from optlight.spec import problem_from_dict

Array = NDArray[np.float64]

#: Closed-loop bandwidth of the computed-torque controller (Hz).
BANDWIDTH_HZ = 10.0
#: Physics steps per control period.
SUBSTEPS = 2
#: Smallest mass (kg) and rotational inertia (kg m²) MuJoCo gives a body (a URDF link of zero mass).
MIN_MASS_KG, MIN_INERTIA = 1e-6, 1e-9


@dataclass(frozen=True)
class SimulationReport:
    """What :func:`simulate` measured. Per joint (``joints``): the largest |q − q_r| over the control
    steps (``tracking_error_rad``), the peak |τ| (``peak_torque_nm``) and its ``torque_limit_nm`` (None:
    no published limits). Per capture: the distance (m) from the light to its planned position at the
    trigger (``trigger_position_error_m``) and the angle (rad) between the light's axis and the
    planned one (``trigger_axis_error_rad``). ``saturated_steps``: control steps where a torque was
    clipped to its limit."""

    controller: str
    rate_hz: float
    timestep_s: float
    duration_s: float
    joints: tuple[str, ...]
    tracking_error_rad: tuple[float, ...]
    peak_torque_nm: tuple[float, ...]
    torque_limit_nm: tuple[float, ...] | None
    saturated_steps: int
    trigger_times_s: tuple[float, ...]
    trigger_position_error_m: tuple[float, ...]
    trigger_axis_error_rad: tuple[float, ...]
    elapsed_s: float

    def to_dict(self) -> dict[str, Any]:
        """Plain JSON-safe data."""
        return json_safe(asdict(self))

    def lines(self) -> list[str]:
        """A readable account: one line per joint, then the light at the triggers."""
        lines = [
            f"MuJoCo, {self.controller} at {self.rate_hz:g} Hz (physics step {self.timestep_s * 1e3:.3g} ms), "
            f"{self.duration_s:.2f} s simulated in {self.elapsed_s:.1f} s",
        ]
        limits = self.torque_limit_nm or (math.nan,) * len(self.joints)
        for j, e, tau, lim in zip(self.joints, self.tracking_error_rad, self.peak_torque_nm, limits, strict=True):
            of = f", {tau / lim:.1%} of {lim:.4g} N·m" if math.isfinite(lim) else " (no published limit)"
            lines.append(f"  {j}: tracking error ≤ {e:.3g} rad; peak |τ| = {tau:.4g} N·m{of}")
        if self.saturated_steps:
            lines.append(f"  torque clipped to a limit at {self.saturated_steps} control steps")
        if self.trigger_position_error_m:
            worst = int(np.argmax(self.trigger_position_error_m))
            lines.append(
                f"light at the {len(self.trigger_times_s)} triggers: position error ≤ "
                f"{max(self.trigger_position_error_m) * 1e3:.4g} mm (capture {worst}), axis error ≤ "
                f"{math.degrees(max(self.trigger_axis_error_rad)):.4g}°"
            )
        return lines


def mjcf_of(dynamics: Dynamics, timestep_s: float) -> str:
    """The MJCF text of the arm and lamp of ``dynamics`` (module docstring), physics step ``timestep_s``."""
    model = dynamics.model
    robot = dynamics.robot
    light = model.frames[robot.light_frame_id]
    limit = dynamics.torque_limit
    children: dict[int, list[int]] = {}
    for j in range(1, model.njoints):
        children.setdefault(int(model.parents[j]), []).append(j)

    def pose(placement: pin.SE3) -> str:
        x, y, z, w = pin.Quaternion(placement.rotation).coeffs()
        return f'pos="{_numbers(placement.translation)}" quat="{_numbers((w, x, y, z))}"'

    def body(j: int, indent: str) -> list[str]:
        joint = model.joints[j]
        kind, axis = joint_axis(model, joint)
        inertia = model.inertias[j]
        c, m, i = inertia.lever, float(inertia.mass), inertia.inertia
        full = _numbers((i[0, 0], i[1, 1], i[2, 2], i[0, 1], i[0, 2], i[1, 2]))
        name = quoteattr(model.names[j])
        lines = [
            f"{indent}<body name={name} {pose(model.jointPlacements[j])}>",
            f'{indent}  <inertial pos="{_numbers(c)}" mass="{max(m, MIN_MASS_KG)!r}" fullinertia="{full}"/>',
            f'{indent}  <joint name={name} type="{"hinge" if kind == "revolute" else "slide"}" '
            f'axis="{_numbers(axis)}" limited="false"/>',
        ]
        if j == light.parentJoint:
            lines.append(f'{indent}  <site name="light" {pose(light.placement)}/>')
        for child in children.get(j, []):
            lines += body(child, indent + "  ")
        return lines + [f"{indent}</body>"]

    motors = []
    for k, j in enumerate(range(1, model.njoints)):
        clip = f' ctrllimited="true" ctrlrange="{_numbers((-limit[k], limit[k]))}"' if limit is not None else ""
        motors.append(f'    <motor joint={quoteattr(model.names[j])} gear="1"{clip}/>')
    tree = [line for j in children.get(0, []) for line in body(j, "    ")]
    return "\n".join(
        [
            f'<mujoco model={quoteattr(robot.name)}>',
            f'  <compiler angle="radian" boundmass="{MIN_MASS_KG!r}" boundinertia="{MIN_INERTIA!r}" balanceinertia="true"/>',
            f'  <option timestep="{timestep_s!r}" integrator="RK4" gravity="0 0 -9.81"/>',
            "  <worldbody>",
            *tree,
            "  </worldbody>",
            "  <actuator>",
            *motors,
            "  </actuator>",
            "</mujoco>",
        ]
    )


def _numbers(values: Any) -> str:
    """Numbers as MJCF writes them: space-separated, each the shortest text that reads back exactly."""
    return " ".join(repr(float(v)) for v in np.ravel(values))


def simulate(
    dynamics: Dynamics,
    reference: Trajectory,
    *,
    rate_hz: float,
    trigger_times: Array,
    planned_positions: Array,
    planned_axes: Array,
    bandwidth_hz: float = BANDWIDTH_HZ,
) -> SimulationReport:
    """Run ``reference`` (q, q̇, q̈ of the joints, rad) through the computed-torque controller at
    ``rate_hz`` on the MuJoCo model of ``dynamics`` (module docstring); compare the light at each of
    ``trigger_times`` (M,) s with ``planned_positions`` (M, 3) m and ``planned_axes`` (M, 3) unit."""
    import mujoco

    start = time.perf_counter()
    period = 1.0 / rate_hz
    model = mujoco.MjModel.from_xml_string(mjcf_of(dynamics, period / SUBSTEPS))
    data = mujoco.MjData(model)
    light = model.site("light").id
    n = model.nv
    steps = int(math.floor(reference.duration * rate_hz + 1e-9))
    grid = np.arange(steps + 1) * period
    q_r, qd_r, qdd_r = reference.sample(np.minimum(grid, reference.duration))
    data.qpos[:], data.qvel[:] = q_r[0], qd_r[0]
    omega = 2 * math.pi * bandwidth_hz
    limit = dynamics.torque_limit
    error = np.zeros(n)
    peak = np.zeros(n)
    saturated = 0
    triggers = sorted(float(t) for t in trigger_times)
    order = np.argsort(trigger_times)
    positions, axes = np.zeros((len(triggers), 3)), np.zeros((len(triggers), 3))
    found = 0
    for k in range(steps):
        q, qd = data.qpos.copy(), data.qvel.copy()
        error = np.maximum(error, np.abs(q - q_r[k]))
        # τ = M(q) u + b(q, q̇) by MuJoCo's inverse dynamics at the measured state
        data.qacc[:] = qdd_r[k] + omega**2 * (q_r[k] - q) + 2 * omega * (qd_r[k] - qd)
        mujoco.mj_inverse(model, data)
        tau = data.qfrc_inverse.copy()
        if limit is not None:
            saturated += int(np.any(np.abs(tau) > limit))
            tau = np.clip(tau, -limit, limit)
        peak = np.maximum(peak, np.abs(tau))
        data.ctrl[:] = tau
        # the physics steps of this period, split at the triggers in it
        ends = [grid[k] + (s + 1) * period / SUBSTEPS for s in range(SUBSTEPS)]
        stops = sorted({*ends, *(t for t in triggers[found:] if grid[k] < t <= grid[k + 1])})
        for stop in stops:
            model.opt.timestep = stop - data.time
            if model.opt.timestep > 1e-12:
                mujoco.mj_step(model, data)
            data.time = stop
            while found < len(triggers) and triggers[found] <= stop + 1e-12:
                mujoco.mj_kinematics(model, data)
                positions[found] = data.site_xpos[light]
                axes[found] = data.site_xmat[light].reshape(3, 3)[:, 2]
                found += 1
    mujoco.mj_forward(model, data)
    error = np.maximum(error, np.abs(data.qpos - q_r[-1]))
    if found < len(triggers):
        raise OptlightError(f"simulate: {len(triggers) - found} trigger times lie after the trajectory's end")
    planned_p = np.asarray(planned_positions, float)[order]
    planned_a = np.asarray(planned_axes, float)[order]
    position_error = np.linalg.norm(positions - planned_p, axis=1)
    cosine = np.clip(np.einsum("ij,ij->i", axes, planned_a), -1.0, 1.0)
    unsorted = np.empty_like(position_error), np.empty_like(position_error)
    unsorted[0][order], unsorted[1][order] = position_error, np.arccos(cosine)
    return SimulationReport(
        controller="computed torque",
        rate_hz=float(rate_hz),
        timestep_s=period / SUBSTEPS,
        duration_s=float(grid[-1]),
        joints=tuple(dynamics.robot.joint_names),
        tracking_error_rad=tuple(error.tolist()),
        peak_torque_nm=tuple(peak.tolist()),
        torque_limit_nm=None if limit is None else tuple(np.asarray(limit, float).tolist()),
        saturated_steps=saturated,
        trigger_times_s=tuple(float(t) for t in np.asarray(trigger_times, float)),
        trigger_position_error_m=tuple(unsorted[0].tolist()),
        trigger_axis_error_rad=tuple(unsorted[1].tolist()),
        elapsed_s=time.perf_counter() - start,
    )


def simulate_folder(folder: str | Path) -> SimulationReport:
    """:func:`simulate` a results folder: its problem (plan.json) rebuilt into the robot and the lamp,
    joint_trajectory.yaml as the reference, captures.csv's triggers and planned light positions (the
    planned axes from its joint angles), plan.json's controller rate. Raises :class:`UsageError` for a
    folder without those files, or without MuJoCo installed."""
    folder = Path(folder)
    option = "RESULTS_DIR"
    try:
        import mujoco  # noqa: F401 - only to say it is missing before any work
    except ImportError:
        raise UsageError(option, "simulating needs MuJoCo: pip install 'optlight[sim]'") from None
    needed = ("plan.json", "joint_trajectory.yaml", "captures.csv")
    missing = [f for f in needed if not (folder / f).is_file()]
    if missing:
        raise UsageError(option, f"{folder} is not an optlight results folder (no {', '.join(missing)})")
    try:
        plan = json.loads((folder / "plan.json").read_text())
        source = Path(plan["problem_file"]) if plan.get("problem_file") else None
        problem = problem_from_dict(plan["problem"], source=source)
        rate_hz = float(plan["timing"]["csv_rate_hz"])
    except (ValueError, KeyError, TypeError) as e:
        raise UsageError(option, f"{folder / 'plan.json'} does not hold a plan optlight wrote ({e})") from None
    robot = load_robot(problem)
    dynamics = Dynamics(robot, lamp_of(problem))
    try:
        reference = read_joint_trajectory(folder / "joint_trajectory.yaml")
    except ValueError as e:
        raise UsageError(option, str(e)) from None
    if list(reference.joint_names or ()) != robot.joint_names:
        raise UsageError(option, f"joint_trajectory.yaml's joints are not {robot.name}'s {robot.joint_names}")
    with (folder / "captures.csv").open(newline="") as f:
        rows = list(csv.DictReader(f))
    try:
        triggers = np.array([float(r["trigger_s"]) for r in rows])
        positions = np.array([[float(r[f"light_position_{a}_m"]) for a in "xyz"] for r in rows]).reshape(-1, 3)
        q = np.array([[float(r[f"q_{j}"]) for j in robot.joint_names] for r in rows]).reshape(-1, robot.n)
    except (KeyError, ValueError) as e:
        raise UsageError(option, f"{folder / 'captures.csv'} lacks a column optlight writes ({e})") from None
    axes = np.array([robot.light_pose(theta)[1][:, 2] for theta in q]).reshape(-1, 3)
    return simulate(
        dynamics, reference, rate_hz=rate_hz, trigger_times=triggers, planned_positions=positions, planned_axes=axes
    )
