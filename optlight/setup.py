"""A problem built once into the objects every stage shares.

``Setup.from_problem(problem)`` builds, in this order and each exactly once:

- the object (mesh, albedo) and its ray intersector, the camera and the G-buffer: ``scene`` at the
  camera's resolution (reported costs, figures) and ``search_scene`` at ``[landmarks] resolution``
  (the landmark search and the placement NLP), the two sharing the object;
- the objectives on both scenes (``objective``, ``search_objective``), with their reference;
- the robot, and the ``limits`` a plan must keep (its URDF velocity limits times ``[robot]
  velocity_scale``), and its ``dynamics`` with the lamp (``[light] mass_kg``, ``com_m``), whose joint
  torques the verification checks against the robot's torque limits;
- the environment: obstacles and self-collision when ``[environment] enabled``, the camera's view
  (``[view]``) unless it is off; its CasADi clearance and view functions are built on first use and
  kept by the environment;
- the lights the landmark search may use: the allowed cap less the lights whose housing would enter
  the camera's view (``view_zenith``, see :func:`view_zenith`);
- the start configuration (``[robot] start``; unset, the robot's reference configuration, or the
  clear configuration nearest it when the reference is not clear: ``start_note`` says which);
- the generalized IK's settings from ``[solver]``.

The planners take neither a ``Setup`` nor a :class:`~optlight.spec.Problem`: they take what
``Setup`` builds for them once, its :class:`~optlight.workcell.Workcell` (``workcell``: robot, allowed
sphere, limits, environment, IK settings, view zenith, start) and
:class:`~optlight.workcell.ImageCosts` (``image_costs``), with their own typed sections
(``landmark_spec``, ``trajectory_spec``, ``lightset_spec``, ``solver``); the solve
(:mod:`optlight.pipeline`) hands them over.
Building a ``Setup`` is also the check of everything a run touches that the problem file alone cannot
show (the mesh loads, the URDF parses and has the frame, the reference image matches the camera, the
object fits in the light sphere, the camera sees it): each such mistake is a
:class:`~optlight.errors.ProblemError` naming the file and the key.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path
from types import MappingProxyType
from typing import Any

import coal
import numpy as np
from numpy.typing import NDArray

from optlight.environment import CAPTURE_SLACK, LIGHT, Environment
from optlight.environment.check import check_configurations
from optlight.errors import ProblemError
from optlight.geometry import LightSphere
from optlight.objectives import Objective
from optlight.robot import Dynamics, Lamp, Robot, ik_settings, load_robot
from optlight.scene import Scene
from optlight.spec import (
    EnvironmentSpec,
    LandmarksSpec,
    LightSetSpec,
    Problem,
    SolverSpec,
    TrajectorySpec,
    load_problem,
)
from optlight.spec.sizing import check_memory, check_trajectory_size, planned_captures
from optlight.workcell import ImageCosts, MotionLimits, Workcell

Array = NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class Setup:
    """Everything a solve shares, built once from a problem (see the module docstring)."""

    problem: Problem
    scene: Scene
    search_scene: Scene
    objective: Objective
    search_objective: Objective
    robot: Robot
    limits: MotionLimits
    environment: Environment | None
    ik: Mapping[str, Any]
    start: Array
    view_zenith: float
    dynamics: Dynamics
    start_note: str | None = None

    @classmethod
    def from_problem(cls, problem: Problem | str | Path) -> Setup:
        """Build the setup of a problem (a :class:`Problem`, a file path or a built-in name)."""
        problem = problem if isinstance(problem, Problem) else load_problem(problem)
        check_memory(problem)  # this machine's memory (spec.sizing.check_memory), before the large allocations
        scene = Scene.from_problem(problem)
        search_scene = _search_scene(scene, problem.landmarks.resolution)
        objective = Objective.from_problem(problem, scene)
        search_objective = (
            objective if search_scene is scene else Objective.from_problem(problem, search_scene)
        )
        robot = load_robot(problem)
        limits = MotionLimits.of(robot, problem.robot.velocity_scale)
        check_trajectory_size(
            problem,
            joints=robot.n,
            reach_m=reach_bound(robot),
            velocity=limits.velocity,
            acceleration=limits.acceleration,
            jerk=limits.jerk,
            captures=planned_captures(problem),
        )
        environment = (
            Environment.from_problem(problem, scene.mesh.vertices)
            if problem.environment.enabled or problem.view.mode != "off"
            else None
        )
        if environment is not None and environment.collisions:
            _check_fixed_clearance(problem, robot, environment)
        start, start_note = _start_configuration(problem, robot, environment)
        return cls(
            problem=problem,
            scene=scene,
            search_scene=search_scene,
            objective=objective,
            search_objective=search_objective,
            robot=robot,
            limits=limits,
            environment=environment,
            ik=MappingProxyType(ik_settings(problem.solver)),
            start=start,
            view_zenith=view_zenith(problem, scene.sphere, environment, robot),
            dynamics=Dynamics(robot, lamp_of(problem)),
            start_note=start_note,
        )

    @cached_property
    def workcell(self) -> Workcell:
        """What the planners share of the robot and its cell (:class:`~optlight.workcell.Workcell`),
        built once per setup."""
        sphere = dataclasses.replace(
            self.scene.sphere, zenith_min=max(self.scene.sphere.zenith_min, self.view_zenith)
        )
        return Workcell(
            robot=self.robot,
            sphere=sphere,
            limits=self.limits,
            environment=self.environment,
            ik=self.ik,
            view_zenith=self.view_zenith,
            start=self.start,
        )

    @cached_property
    def image_costs(self) -> ImageCosts:
        """The objective on the camera's and on the search scene
        (:class:`~optlight.workcell.ImageCosts`), built once per setup."""
        return ImageCosts(self.scene, self.objective, self.search_scene, self.search_objective)

    @property
    def sphere(self) -> LightSphere:
        """The light sphere (centre O, radius b, frame) with the zenith range the lights may use:
        ``[light_sphere]``'s, less the lights whose housing would enter the camera's view."""
        return self.workcell.sphere

    @property
    def landmark_spec(self) -> LandmarksSpec:
        """``[landmarks]``: how the landmark search runs."""
        return self.problem.landmarks

    @property
    def lightset_spec(self) -> LightSetSpec:
        """``[lightset]``: the light set to design or map (kind "none": the landmark search)."""
        return self.problem.lightset

    @property
    def trajectory_spec(self) -> TrajectorySpec:
        """``[trajectory]``: order, path mode, knot spacing, dwell."""
        return self.problem.trajectory

    @property
    def solver(self) -> SolverSpec:
        """``[solver]``: IPOPT's and the IK's settings."""
        return self.problem.solver

    @property
    def environment_spec(self) -> EnvironmentSpec:
        """``[environment]`` as written (``environment`` is the built one, or None when disabled)."""
        return self.problem.environment

    @property
    def file(self) -> str:
        """The problem file's path for error messages ("<inline>" for a problem built in code)."""
        return str(self.problem.source) if self.problem.source else "<inline>"


def reach_bound(robot: Robot) -> float:
    """An upper bound R (m) of the distance from any joint's axis to the light, whatever the joint
    angles: the lengths of the joint placements after the first joint and the light's placement in its
    joint, added up along the chain, with each prismatic joint's longest stroke. A joint of speed q̇
    moves the light by at most |q̇| R (revolute) or |q̇| (prismatic, counted as R ≥ 1 m)."""
    model = robot.model
    frame = model.frames[robot.light_frame_id]
    total = float(np.linalg.norm(frame.placement.translation))
    chain = []
    joint = frame.parentJoint
    while joint > 0:
        chain.append(joint)
        joint = model.parents[joint]
    for j in chain[:-1]:  # the first joint's own placement does not move with any joint
        total += float(np.linalg.norm(model.jointPlacements[j].translation))
    for j in chain:
        if "P" in model.joints[j].shortname().removeprefix("JointModel"):
            q = model.joints[j].idx_q
            total += float(max(abs(model.lowerPositionLimit[q]), abs(model.upperPositionLimit[q])))
    return max(total, 1.0)


def lamp_of(problem: Problem) -> Lamp:
    """The lamp of ``[light]`` as a rigid body: ``mass_kg``, ``com_m`` and the housing's cylinder."""
    light = problem.light
    return Lamp(light.mass_kg, light.com_m, light.housing_radius_m, light.housing_length_m)


def _search_scene(scene: Scene, resolution: int) -> Scene:
    """``scene`` itself, or the same view with its longer side at ``resolution`` px when that is
    smaller (the landmark search renders there)."""
    cam = scene.camera
    if resolution >= max(cam.width, cam.height):
        return scene
    if cam.width >= cam.height:
        return scene.resampled(resolution, max(1, round(resolution * cam.height / cam.width)))
    return scene.resampled(max(1, round(resolution * cam.width / cam.height)), resolution)


def housing_clearance(sphere: LightSphere, environment: Environment, zenith: float) -> float:
    """Distance (m, < 0 when they meet) between the light housing and the camera's view cone, the
    light at ``zenith`` (rad) on the sphere, aimed at O (any azimuth: the cone is symmetric about the
    pole): coal's exact distance between the housing shape (``environment.housing``, centred
    ``housing_offset`` behind the emitting point, away from O) and the cone."""
    cone = environment.view_cone
    assert cone is not None
    d = sphere.direction(zenith, 0.0)
    helper = np.array([1.0, 0.0, 0.0]) if abs(d[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    x = np.cross(helper, d)
    x /= np.linalg.norm(x)
    centre = sphere.center + (sphere.radius + environment.housing_offset) * d
    housing = coal.Transform3s(np.column_stack([x, np.cross(d, x), d]), centre)
    place = cone.placement
    return float(
        coal.distance(
            environment.housing,
            housing,
            cone.coal_geometry(),
            coal.Transform3s(place.rotation, place.translation),
            coal.DistanceRequest(),
            coal.DistanceResult(),
        )
    )


#: Rolls of the light about its axis at which :func:`housing_sphere_clearance` evaluates the housing's
#: spheres (their fit need not be symmetric about the axis).
ROLLS = 12


def housing_sphere_clearance(
    sphere: LightSphere, environment: Environment, robot: Robot, zenith: float
) -> float:
    """The same as :func:`housing_clearance` for the NLPs' model of the housing: the smallest
    sd_cone(c) − r (m) over its fitted spheres (:class:`~optlight.environment.RobotSpheres`, body
    "light") and over :data:`ROLLS` rolls of the light about its axis (the roll is free)."""
    cone = environment.view_cone
    assert cone is not None
    spheres = environment.collision_model(robot).spheres
    light = [i for i, b in enumerate(spheres.bodies) if b.name == LIGHT][0]
    body = spheres.bodies[light]
    # sphere centres in the light frame: the body's are in its joint's frame
    frame = robot.model.frames[robot.light_frame_id].placement
    centres = (body.centers - frame.translation) @ frame.rotation
    d = sphere.direction(zenith, 0.0)
    z = -d  # the light emits towards O
    x0 = np.cross([1.0, 0.0, 0.0] if abs(z[0]) < 0.9 else [0.0, 1.0, 0.0], z)
    x0 /= np.linalg.norm(x0)
    y0 = np.cross(z, x0)
    a = sphere.center + sphere.radius * d
    worst = math.inf
    for roll in np.linspace(0.0, 2 * np.pi, ROLLS, endpoint=False):
        x = math.cos(roll) * x0 + math.sin(roll) * y0
        rotation = np.column_stack([x, np.cross(z, x), z])
        world = a + centres @ rotation.T
        worst = min(worst, float(np.min(cone.signed_distance(world) - body.radii)))
    return worst


def view_zenith(
    problem: Problem, sphere: LightSphere, environment: Environment | None, robot: Robot
) -> float:
    """The smallest zenith (rad) at which the light housing clears the camera's view cone (0 when the
    view is off): lights nearer the camera's axis would put the lamp in front of the lens. Clear means
    both exactly (:func:`housing_clearance`) and for the NLPs' spheres (:func:`housing_sphere_clearance`,
    by :data:`~optlight.environment.CAPTURE_SLACK` as the placements' rows), so that every light the
    search proposes is one the placement and trajectory NLPs can hold. Found by
    bisection (the clearance grows with the zenith) to 1e-7 rad and rounded up; a
    :class:`ProblemError` naming ``light_sphere.zenith_max_deg`` when no light of the cap is clear."""
    if environment is None or environment.view_cone is None:
        return 0.0

    def clear(zenith: float) -> bool:
        return (
            housing_clearance(sphere, environment, zenith) >= 0.0
            and housing_sphere_clearance(sphere, environment, robot, zenith) >= CAPTURE_SLACK
        )

    lo, hi = sphere.zenith_min, sphere.zenith_max
    if clear(lo):
        return 0.0
    if not clear(hi):
        raise ProblemError(
            str(problem.source) if problem.source else "<inline>",
            "light_sphere.zenith_max_deg",
            "a light cap that reaches out of the camera's view (the housing of [light] is in the view "
            'cone at every allowed zenith; widen the cap, move the camera back, or set [view] mode = "off")',
            problem.light_sphere.zenith_max_deg,
        )
    while hi - lo > 1e-7:
        mid = 0.5 * (lo + hi)
        lo, hi = (lo, mid) if clear(mid) else (mid, hi)
    return hi


#: Turns of the first joint (rad) tried first for a clear start: the arm turned away as a whole.
START_TURNS = tuple(np.deg2rad(a) for a in (30, -30, 60, -60, 90, -90, 120, -120, 150, -150, 180, -180))
#: Random configurations around θ_ref tried next, per spread σ (rad) of :data:`START_SPREADS`.
START_SAMPLES = 150
START_SPREADS = (0.3, 0.6, 1.2)
#: A chosen start keeps every sphere row (clearance and view) at least this far inside (m): none more
#: than the reference configuration itself (rows whose margin is lowered there keep 5 mm).
START_SLACK_M = 0.0


def _sphere_rows_clear(environment: Environment, robot: Robot, theta: Array, slack: float) -> tuple[bool, float, str]:
    """Whether the NLPs' rows at θ (rad) — the clearance rows when obstacles and self-collision are
    modelled, the view rows when the view is kept clear along the whole motion (``[view] mode =
    "path"``; at the captures only, the start may stand in the view) — are all ≥ ``slack`` (m); the
    worst row (m) and its label."""
    # the beam matters at the captures only, never at the start
    clearance, view = environment.sphere_clearance(robot, theta, beam=False)
    labels = (*environment.clearance_labels(robot), *environment.view_labels(robot, beam=False))
    n_clearance = len(clearance)
    if environment.view_mode != "path":
        labels, view = labels[:n_clearance], np.zeros(0)
    if not environment.collisions:
        labels, clearance = labels[n_clearance:], np.zeros(0)
    rows = np.concatenate([clearance, view])
    if not rows.size:
        return True, math.inf, ""
    k = int(np.argmin(rows))
    return bool(rows[k] >= slack), float(rows[k]), labels[k]


def _exactly_clear(environment: Environment, robot: Robot, theta: Array) -> bool:
    """Coal's exact check of θ: obstacles, self-collision and (``[view] mode = "path"``) the camera's
    view."""
    mode = "path" if environment.view_mode == "path" else "off"
    model = environment.collision_model(robot)
    return check_configurations(model, theta[None, :], np.zeros(1), view=mode).passed


def clear_start(robot: Robot, environment: Environment, seed: int = 0) -> Array | None:
    """The configuration nearest θ_ref (Euclidean, rad) among the candidates — θ_ref with its first
    joint turned by :data:`START_TURNS`, then :data:`START_SAMPLES` random configurations per spread
    of :data:`START_SPREADS` around it, clipped to the limits — whose sphere rows are all ≥
    :data:`START_SLACK_M` and which coal's exact check finds clear of the obstacles, of itself and
    (``[view] mode = "path"``) out of the camera's view; None when no candidate is. Seeded: the same
    cell, the same start."""
    reference = np.asarray(robot.theta_ref, float)
    rng = np.random.default_rng(seed)
    candidates = []
    for turn in START_TURNS:
        theta = reference.copy()
        theta[0] += turn
        candidates.append(theta)
    for spread in START_SPREADS:
        candidates += list(reference + rng.normal(0.0, spread, size=(START_SAMPLES, robot.n)))
    candidates = [np.clip(t, robot.lower, robot.upper) for t in candidates]
    clear = [t for t in candidates if _sphere_rows_clear(environment, robot, t, START_SLACK_M)[0]]
    for theta in sorted(clear, key=lambda t: float(np.linalg.norm(t - reference))):
        if _exactly_clear(environment, robot, theta):
            return theta
    return None


def _start_configuration(
    problem: Problem, robot: Robot, environment: Environment | None
) -> tuple[Array, str | None]:
    """θ_start (rad) from ``[robot] start`` and a note when it is not what the file says: joint
    angles, an SRDF configuration's name, or (unset) the robot's reference configuration — or, when
    that is not clear of the environment (and of the camera's view with ``[view] mode = "path"``; the
    NLPs' sphere rows), the clear
    configuration nearest it (:func:`clear_start`), with a note saying so. A :class:`ProblemError`
    naming ``robot.start`` when it has the wrong length, lies outside the joint limits, is not a
    configuration of the SRDF, or (given) puts the robot into an obstacle or itself
    (``[environment] enabled``): the message then proposes a clear start when one is found."""
    file = str(problem.source) if problem.source else "<inline>"
    value = problem.robot.start
    if value is None:
        theta = np.asarray(robot.theta_ref, float)
        if environment is None:
            return theta, None
        ok, worst, label = _sphere_rows_clear(environment, robot, theta, 0.0)
        if ok:
            return theta, None
        chosen = clear_start(robot, environment)
        what = f"{label} {-worst * 1e3:.1f} mm too close" if "view_cone" not in label else f"{label}: in the camera's view"
        if chosen is None:
            raise ProblemError(
                file,
                "robot.start",
                f"a start configuration clear of the environment and the camera's view: the reference "
                f"configuration of {robot.name} is not ({what}) and none near it is; set [robot] start",
            )
        note = (
            f"the reference configuration of {robot.name} is not clear ({what}): the plan starts and "
            f"ends at the clear configuration nearest it, [robot] start = {_angles(chosen)} "
            "(set [robot] start to choose another)"
        )
        return chosen, note
    if isinstance(value, str):
        if value not in robot.named_configurations:
            names = ", ".join(sorted(robot.named_configurations)) or "none in its SRDF"
            raise ProblemError(
                file, "robot.start", f"joint angles or a configuration of {robot.name} ({names})", value
            )
        theta = robot.named_configurations[value]
    else:
        theta = np.asarray(value, float)
        if theta.shape != (robot.n,):
            raise ProblemError(file, "robot.start", f"{robot.n} joint angles for {robot.name}", list(value))
        if not robot.within_limits(theta, tol=0.0):
            raise ProblemError(
                file,
                "robot.start",
                f"joint angles within the limits of {robot.name} "
                f"({', '.join(f'[{lo:.3g}, {hi:.3g}]' for lo, hi in zip(robot.lower, robot.upper, strict=True))} rad)",
                list(value),
            )
    if environment is not None and environment.collisions:
        clearance, _ = environment.sphere_clearance(robot, theta, beam=False)
        if clearance.size and clearance.min() < 0.0:
            label = environment.clearance_labels(robot)[int(np.argmin(clearance))]
            chosen = clear_start(robot, environment)
            hint = f"; e.g. [robot] start = {_angles(chosen)} is clear" if chosen is not None else ""
            raise ProblemError(
                file,
                "robot.start",
                f"a configuration clear of the environment ({label} is {-clearance.min() * 1e3:.1f} mm "
                f"too close{hint})",
                value,
            )
    return theta, None


def _check_fixed_clearance(problem: Problem, robot: Robot, environment: Environment) -> None:
    """A :class:`ProblemError` naming ``environment.table_height_m``, with the highest table top that
    works, when a body whose height over the table no motion changes (on a first joint turning about
    the vertical, :attr:`~optlight.environment.CollisionModel.fixed_obstacle_distance`) is closer to
    it than ``[environment] margin_m``: no plan could clear it."""
    model = environment.collision_model(robot)
    for (body, obstacle), distance in sorted(model.fixed_obstacle_distance.items()):
        table = problem.environment.table_height_m
        if distance >= environment.margin or obstacle != "table" or table is None:
            continue
        highest = math.floor((table - (environment.margin - distance)) * 1e3) / 1e3  # mm, rounded down
        raise ProblemError(
            str(problem.source) if problem.source else "<inline>",
            "environment.table_height_m",
            f"a table top at most {highest:.3f} m: {body} of {robot.name} "
            f"turns about the vertical {distance * 1e3:.1f} mm above the table, closer than [environment] "
            f"margin_m = {environment.margin:g} m in every configuration",
            table,
        )


def _angles(theta: Array) -> str:
    """Joint angles as a problem file writes them: ``[0.123, -1.571, …]`` (rad, 3 decimals)."""
    return "[" + ", ".join(f"{t:.3f}" for t in theta) + "]"
