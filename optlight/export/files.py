"""The file writers of a plan: lights.lp, the controller's joint_trajectory.yaml and its
FollowJointTrajectory goal (and their reader), captures.csv and JSON."""

from __future__ import annotations

import csv
import json
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import orjson
import yaml
from numpy.typing import ArrayLike, NDArray

from optlight.jsondata import json_safe
from optlight.motion import Trajectory
from optlight.planning.waypoints import Waypoints
from optlight.spec.sizing import image_names

Array = NDArray[np.float64]

#: The controller's files: the waypoints as a JointTrajectory, and as a FollowJointTrajectory goal.
JOINT_TRAJECTORY = "joint_trajectory.yaml"
FOLLOW_JOINT_TRAJECTORY_GOAL = "follow_joint_trajectory_goal.yaml"
#: How long after the last waypoint's time the joints may take to reach it, in the goal (s).
GOAL_TIME_TOLERANCE_S = 0.5
#: The frame of every light direction optlight writes (captures.csv, lights.lp, light_directions.txt).
LIGHT_FRAME = (
    "unit vector from the object towards the light; x to the right of the image, y towards its top, "
    "z towards the camera (the OpenCV camera frame's (x, -y, -z))"
)
#: captures.csv's columns of the light direction, in :data:`LIGHT_FRAME`.
LIGHT_DIRECTION_COLUMNS = ("light_dir_right", "light_dir_up", "light_dir_to_camera")
#: captures.csv's last columns: the exposure's start and end (s) and the light's motion during it
#: (the angle it turns about the object's centre, deg, and the distance it travels, mm).
EXPOSURE_COLUMNS = ("exposure_start_s", "exposure_end_s", "blur_deg", "blur_mm")


def lp_direction(d_camera: ArrayLike) -> Array:
    """Light direction(s) in .lp coordinates from unit vector(s) d (..., 3) in the OpenCV camera
    frame pointing from the object towards the light: (d_x, −d_y, −d_z).

    A frontal light between object and camera (d = (0, 0, −1)) gives (0, 0, 1); a light above the
    object (d_y < 0, the image's y axis points down) gives y > 0.
    """
    d = np.asarray(d_camera, float)
    if d.shape[-1:] != (3,):
        raise ValueError(f"directions must have shape (..., 3), got {d.shape}")
    return d * np.array([1.0, -1.0, -1.0])


def lp_text(filenames: Sequence[str], directions_lp: ArrayLike) -> str:
    """The content of a .lp file: the image count, then ``filename x y z`` per image."""
    d = np.asarray(directions_lp, float).reshape(-1, 3)
    if len(filenames) != len(d):
        raise ValueError(f"{len(filenames)} file names for {len(d)} light directions")
    # a component that rounds to zero is written 0.000000000: a residue of −8e-17 (the default plan's
    # first light, straight to the right) printed as −0.000000000
    d = np.where(np.abs(d) < 5e-10, 0.0, d)
    lines = [str(len(d))]
    lines.extend(f"{name} {x:.9f} {y:.9f} {z:.9f}" for name, (x, y, z) in zip(filenames, d, strict=True))
    return "\n".join(lines) + "\n"


def _yaml_float(x: float) -> str:
    """A float YAML 1.1 readers (PyYAML) parse back exactly: repr, with a '.0' where the mantissa of
    an exponent form has no point ('1e-05' would be read as a string)."""
    text = repr(float(x))
    mantissa, _, exponent = text.partition("e")
    if exponent and "." not in mantissa:
        text = f"{mantissa}.0e{exponent}"
    return text


def joint_trajectory_text(waypoints: Waypoints, joint_names: Sequence[str]) -> str:
    """joint_trajectory.yaml (module docstring): the controller ``waypoints``
    (:func:`optlight.planning.waypoints.controller_waypoints`), each with its positions, velocities,
    accelerations and ``time_from_start`` (the nanoseconds the points were sampled at, so the file's
    points are exact)."""
    names = list(joint_names)
    if len(names) != waypoints.q.shape[1] or len(set(names)) != len(names):
        raise ValueError(f"{len(names)} joint names (distinct) are needed for {waypoints.q.shape[1]} joints")
    q, qd, qdd = waypoints.q, waypoints.qd, waypoints.qdd
    if not (np.isfinite(q).all() and np.isfinite(qd).all() and np.isfinite(qdd).all()):
        raise ValueError("the waypoints have non-finite values")
    lines = [
        "header: {stamp: {sec: 0, nanosec: 0}, frame_id: \"\"}",
        "joint_names: [" + ", ".join(json.dumps(n) for n in names) + "]",
        "points:",
    ]
    for ns, positions, velocities, accelerations in zip(
        waypoints.nanoseconds.tolist(), _yaml_rows(q), _yaml_rows(qd), _yaml_rows(qdd), strict=True
    ):
        lines.append(
            f"  - positions: {positions}\n"
            f"    velocities: {velocities}\n"
            f"    accelerations: {accelerations}\n"
            "    effort: []\n"
            f"    time_from_start: {{sec: {ns // 1_000_000_000}, nanosec: {ns % 1_000_000_000}}}"
        )
    return "\n".join(lines) + "\n"


def follow_joint_trajectory_goal_text(
    waypoints: Waypoints, joint_names: Sequence[str], goal_time_tolerance_s: float = GOAL_TIME_TOLERANCE_S
) -> str:
    """follow_joint_trajectory_goal.yaml: a ``control_msgs/action/FollowJointTrajectory`` goal, its
    ``trajectory`` the text of :func:`joint_trajectory_text` and ``goal_time_tolerance`` (s) how long
    after the last point's time the joints may take to reach it (the default path and goal
    tolerances of the controller's configuration apply). ``ros2 action send_goal`` takes it as it is
    (docs/robot.md)."""
    if not (np.isfinite(goal_time_tolerance_s) and goal_time_tolerance_s >= 0):
        raise ValueError(f"goal_time_tolerance_s must be a non-negative number, got {goal_time_tolerance_s}")
    trajectory = joint_trajectory_text(waypoints, joint_names)
    ns = round(goal_time_tolerance_s * 1e9)
    return (
        "trajectory:\n"
        + "".join(f"  {line}\n" for line in trajectory.splitlines())
        + f"goal_time_tolerance: {{sec: {ns // 1_000_000_000}, nanosec: {ns % 1_000_000_000}}}\n"
    )


def _yaml_rows(values: Array) -> list[str]:
    """Each row of ``values`` (K, n) as a YAML flow sequence of :func:`_yaml_float` texts.

    The same text as calling it per value, ~10× faster: orjson writes the shortest round-trip
    digits (Ryu, in C; ~25 ns a number against ``repr``'s ~0.5 µs), which are ``repr``'s digits and,
    from 1e-4 up, its notation too. Only the exponent forms go through :func:`_yaml_float`: below
    1e-4 (orjson writes ``0.00001`` where ``repr`` writes ``1e-05``) and from 1e16 (``1e+16``, whose
    mantissa needs a point)."""
    flat = np.ascontiguousarray(values, dtype=np.float64).ravel()
    texts = orjson.dumps(flat, option=orjson.OPT_SERIALIZE_NUMPY).decode()[1:-1].split(",")
    magnitude = np.abs(flat)
    exponent_form = np.flatnonzero((flat != 0.0) & ((magnitude < 1e-4) | (magnitude >= 1e16)))
    for i, x in zip(exponent_form.tolist(), flat[exponent_form].tolist(), strict=True):
        texts[i] = _yaml_float(x)
    n = values.shape[1]
    return ["[" + ", ".join(texts[i : i + n]) + "]" for i in range(0, len(texts), n)]


def write_joint_trajectory(folder: str | Path, waypoints: Waypoints, joint_names: Sequence[str]) -> list[Path]:
    """Write joint_trajectory.yaml (:func:`joint_trajectory_text`) and follow_joint_trajectory_goal.yaml
    (:func:`follow_joint_trajectory_goal_text`) into ``folder``; returns their paths."""
    out = Path(folder)
    files = [out / JOINT_TRAJECTORY, out / FOLLOW_JOINT_TRAJECTORY_GOAL]
    files[0].write_text(joint_trajectory_text(waypoints, joint_names))
    files[1].write_text(follow_joint_trajectory_goal_text(waypoints, joint_names))
    return files


def read_joint_trajectory(path: str | Path, *, landmark_intervals: ArrayLike | None = None) -> Trajectory:
    """Read a ``trajectory_msgs/JointTrajectory`` YAML file (as :func:`write_joint_trajectory` writes)
    into a :class:`Trajectory` joining its points by quintic Hermite polynomials
    (:meth:`Trajectory.from_points`), which reproduces positions, velocities and accelerations at every
    point. ``landmark_intervals`` restores the dwells (the message does not hold them).

    Raises ValueError naming what is missing or malformed.
    """
    path = Path(path)
    loader = getattr(yaml, "CSafeLoader", yaml.SafeLoader)
    with path.open() as f:
        doc = yaml.load(f, Loader=loader)  # noqa: S506 - a safe loader
    if not isinstance(doc, dict) or "joint_names" not in doc or "points" not in doc:
        raise ValueError(f"{path}: expected a JointTrajectory with joint_names and points")
    names = [str(n) for n in doc["joint_names"]]
    points = doc["points"]
    if not isinstance(points, list) or len(points) < 2:
        raise ValueError(f"{path}: points must be a list of at least two points")
    fields = ("positions", "velocities", "accelerations")
    try:
        ns = [int(p["time_from_start"]["sec"]) * 1_000_000_000 + int(p["time_from_start"]["nanosec"]) for p in points]
        t = np.array(ns, float) / 1e9  # as the writer computed the times it sampled
        q, qd, qdd = (np.array([p[f] for p in points], float) for f in fields)
    except (KeyError, TypeError, ValueError) as e:
        raise ValueError(
            f"{path}: every point needs {', '.join(fields)} and time_from_start {{sec, nanosec}} ({e})"
        ) from None
    if q.ndim != 2 or q.shape[1] != len(names):
        raise ValueError(f"{path}: every point needs {len(names)} positions, velocities and accelerations")
    return Trajectory.from_points(t, q, qd, qdd, joint_names=names, landmark_intervals=landmark_intervals)


def write_captures(
    path: str | Path,
    trajectory: Trajectory,
    *,
    settle_s: float,
    image_pattern: str,
    light_directions_camera: ArrayLike,
    light_positions: ArrayLike,
    light_angles_deg: ArrayLike,
    joint_names: Sequence[str],
    exposures: tuple[ArrayLike, ArrayLike, ArrayLike] | None = None,
) -> Path:
    """Write captures.csv (module docstring): one row per dwell of ``trajectory``; the trigger is the
    dwell's start plus ``settle_s`` (0 ≤ settle_s < each dwell's length), or the instant of a dwell of
    zero length (a flying capture, :meth:`Trajectory.trigger_times`), the joint angles are the
    trajectory's at the trigger. Per capture: the direction (unit, OpenCV camera frame; written in
    :data:`LIGHT_FRAME`), the position (m, world) and the (zenith, azimuth) in degrees; with
    ``exposures`` = (windows (M, 2) s, blur angles (M,) rad, blur distances (M,) m), the exposure's
    start and end and the blur (deg, mm) as the last four columns."""
    intervals = trajectory.landmark_intervals
    m = intervals.shape[0]
    directions = lp_direction(np.asarray(light_directions_camera, float).reshape(-1, 3))
    positions = np.asarray(light_positions, float).reshape(-1, 3)
    angles = np.asarray(light_angles_deg, float).reshape(-1, 2)
    if directions.shape[0] != m or positions.shape[0] != m or angles.shape[0] != m:
        raise ValueError(f"expected {m} light directions, positions and angles, one per capture")
    trigger = trajectory.trigger_times(settle_s)
    names = image_names(image_pattern, m)
    q = trajectory.sample(trigger)[0] if m else np.zeros((0, len(joint_names)))
    extra = np.zeros((m, 0))
    if exposures is not None:
        windows = np.asarray(exposures[0], float).reshape(-1, 2)
        blur = np.column_stack([np.rad2deg(exposures[1]), 1e3 * np.asarray(exposures[2], float)]).reshape(-1, 2)
        if windows.shape[0] != m or blur.shape[0] != m:
            raise ValueError(f"expected {m} exposure windows and blurs, one per capture")
        extra = np.column_stack([windows, blur])
    header = (
        ["capture", "dwell_start_s", "dwell_end_s", "trigger_s", "image", "zenith_deg", "azimuth_deg"]
        + list(LIGHT_DIRECTION_COLUMNS)
        + [f"light_position_{a}_m" for a in "xyz"]
        + [f"q_{n}" for n in joint_names]
        + (list(EXPOSURE_COLUMNS) if exposures is not None else [])
    )
    out = Path(path)
    with out.open("w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(header)
        for i in range(m):
            writer.writerow(
                [i, *(f"{x:.9f}" for x in (*intervals[i], trigger[i])), names[i]]
                + [f"{x:.12g}" for x in (*angles[i], *directions[i], *positions[i], *q[i])]
                + [f"{x:.9f}" for x in extra[i, :2]]
                + [f"{x:.6g}" for x in extra[i, 2:]]
            )
    return out


def write_json(path: str | Path, data: Any) -> Path:
    """Write ``data`` (made JSON-safe by :func:`json_safe`) to ``path`` as indented JSON, creating
    the parent folders; returns the path."""
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(json_safe(data), indent=2, allow_nan=False) + "\n")
    return out
