"""Export of a verified plan: trajectory.csv, plan.json, lights.lp, joint_trajectory.yaml and its
FollowJointTrajectory goal, captures.csv and figures (docs/design.md §12).

Nothing is written for a plan that failed verification, and no output is ever left half written or
written over files optlight did not write. The output policy (:func:`check_output_folder`,
:func:`write_folder`, :func:`check_output_file`, :func:`write_file`):

- a folder that does not exist, or an empty one, receives the whole output: the files are written
  into a hidden staging folder that is renamed into place (or, for an existing empty folder, whose
  files are renamed into it) at the end;
- a folder optlight filled before is recognised by its manifest (:data:`MANIFEST`, the list of the
  files optlight wrote there, written last); it is updated only with ``overwrite`` (the command
  line's ``--force``), and then only the files it lists are replaced or removed: files the user
  added there are kept;
- an output written in rounds (``optlight acquire --camera folder``: the user adds the images of a
  round, then runs the command again) says so in its manifest (``"resume": <kind>``, written with
  ``resumable``); a caller continuing that kind of output (``resume``) updates it without
  ``overwrite``, by the same rule: only the files the manifest lists are replaced or removed;
- anything else that exists (a file, a folder holding files optlight did not write, a broken link)
  is refused with a one-line :class:`UsageError`, before any work when the caller checks first;
- a single output file (a PNG) is written to a temporary name beside it and renamed over it; an
  existing file is replaced only with ``overwrite`` and only when it is one optlight wrote (a PNG
  with optlight's mark, :func:`optlight.viz.images.written_by_optlight`), a folder never.

The final renames run with the stop signals (Ctrl-C, SIGTERM, SIGHUP) deferred
(:func:`optlight.interrupts.deferred`), so an output appears whole or not at all; until then a signal
removes the staging folder or temporary file.

lights.lp follows the PTM / relight convention: the first line is the number of images, then one line
``filename x y z`` per image, (x, y, z) the unit vector from the object towards the light with x to
the right of the image, y towards its top and z towards the camera. From a direction d in the OpenCV
camera frame (x right, y down, z forward) that is (d_x, −d_y, −d_z): see :func:`lp_direction`.

joint_trajectory.yaml is a ROS 2 ``trajectory_msgs/JointTrajectory`` (``header``, ``joint_names``,
``points`` with ``positions``, ``velocities``, ``accelerations``, ``effort`` and
``time_from_start: {sec, nanosec}``); with all three of positions, velocities and accelerations,
joint_trajectory_controller interpolates quintically between the points, as
:func:`read_joint_trajectory` does. Its points are the plan's controller waypoints
(:mod:`optlight.planning.waypoints`: every dwell and motion boundary, plus the fewest points the
greedy choice needs for the interpolation to stay within 1e-4 rad of the plan, which the
verification checks), not samples at the controller rate: trajectory.csv has those.
follow_joint_trajectory_goal.yaml is the same trajectory as a ``control_msgs/action/FollowJointTrajectory``
goal, for ``ros2 action send_goal`` (docs/robot.md).

captures.csv has one row per capture: its index, the dwell's start and end, the camera trigger (the
dwell's start plus ``settle_s``), the image file name (the same as in lights.lp), the light's zenith
and azimuth on the light sphere (degrees, the angles ``optlight render --zenith --azimuth`` takes:
zenith from the direction towards the camera, azimuth 0 to the image's right and 90 towards its
top), the light direction in the frame of lights.lp (columns ``light_dir_right``, ``light_dir_up``,
``light_dir_to_camera``), the light position in the world and the joint angles at the trigger.

Light directions: one frame for every file that holds them (captures.csv, lights.lp and the DiLiGenT
folder's ``light_directions.txt``): the unit vector from the object towards the light, x to the
right of the image, y towards its top, z towards the camera (:data:`LIGHT_FRAME`).
"""

from __future__ import annotations

import csv
import datetime
import errno
import importlib.metadata
import json
import os
import shutil
import uuid
from collections.abc import Callable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path, PurePosixPath
from typing import Any

import numpy as np
import orjson
import yaml
from numpy.typing import ArrayLike, NDArray

from optlight import interrupts, locks
from optlight.errors import OutputError, UsageError, VerificationError
from optlight.jsondata import json_safe
from optlight.motion import Trajectory
from optlight.planning.waypoints import Waypoints
from optlight.spec.sizing import image_names
from optlight.verify import VerificationReport

Array = NDArray[np.float64]

#: Distributions whose versions plan.json records.
LIBRARIES = ("numpy", "scipy", "casadi", "pin", "toppra", "ruckig", "meshcat", "optlight")
#: Keys of plan.json written by :func:`write_results` itself; the caller's plan dict may not use them.
RESERVED_KEYS = ("verification", "timing", "versions", "files", "created_utc")
#: The file optlight writes last into every folder it fills: the files it wrote there (JSON).
MANIFEST = ".optlight-manifest.json"
#: The controller's files: the waypoints as a JointTrajectory, and as a FollowJointTrajectory goal.
JOINT_TRAJECTORY = "joint_trajectory.yaml"
FOLLOW_JOINT_TRAJECTORY_GOAL = "follow_joint_trajectory_goal.yaml"
#: How long after the last waypoint's time the joints may take to reach it, in the goal (s).
GOAL_TIME_TOLERANCE_S = 0.5
#: Prefix of the hidden staging folders and temporary files (removed unless the process is killed).
STAGING_PREFIX = ".optlight-staging-"
#: What a failed write's errno means, said before the system's own words.
WRITE_FAILURES = {
    errno.ENOSPC: "the disk is full",
    errno.EDQUOT: "the disk quota is exceeded",
    errno.EFBIG: "a file is larger than this system lets a process write",
}
#: The frame of every light direction optlight writes (captures.csv, lights.lp, light_directions.txt).
LIGHT_FRAME = (
    "unit vector from the object towards the light; x to the right of the image, y towards its top, "
    "z towards the camera (the OpenCV camera frame's (x, -y, -z))"
)
#: captures.csv's columns of the light direction, in :data:`LIGHT_FRAME`.
LIGHT_DIRECTION_COLUMNS = ("light_dir_right", "light_dir_up", "light_dir_to_camera")


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
) -> Path:
    """Write captures.csv (module docstring): one row per dwell of ``trajectory``; the trigger is the
    dwell's start plus ``settle_s`` (0 ≤ settle_s < each dwell's length), the joint angles are the
    trajectory's at the trigger. Per capture: the direction (unit, OpenCV camera frame; written in
    :data:`LIGHT_FRAME`), the position (m, world) and the (zenith, azimuth) in degrees."""
    intervals = trajectory.landmark_intervals
    m = intervals.shape[0]
    directions = lp_direction(np.asarray(light_directions_camera, float).reshape(-1, 3))
    positions = np.asarray(light_positions, float).reshape(-1, 3)
    angles = np.asarray(light_angles_deg, float).reshape(-1, 2)
    if directions.shape[0] != m or positions.shape[0] != m or angles.shape[0] != m:
        raise ValueError(f"expected {m} light directions, positions and angles, one per capture")
    lengths = intervals[:, 1] - intervals[:, 0]
    if not (settle_s >= 0 and np.all(settle_s < lengths)):
        raise ValueError(f"settle_s = {settle_s} s must be ≥ 0 and shorter than every dwell ({lengths.min():.6g} s)")
    names = image_names(image_pattern, m)
    trigger = intervals[:, 0] + settle_s
    q = trajectory.sample(trigger)[0] if m else np.zeros((0, len(joint_names)))
    header = (
        ["capture", "dwell_start_s", "dwell_end_s", "trigger_s", "image", "zenith_deg", "azimuth_deg"]
        + list(LIGHT_DIRECTION_COLUMNS)
        + [f"light_position_{a}_m" for a in "xyz"]
        + [f"q_{n}" for n in joint_names]
    )
    out = Path(path)
    with out.open("w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(header)
        for i in range(m):
            writer.writerow(
                [i, *(f"{x:.9f}" for x in (*intervals[i], trigger[i])), names[i]]
                + [f"{x:.12g}" for x in (*angles[i], *directions[i], *positions[i], *q[i])]
            )
    return out


def write_json(path: str | Path, data: Any) -> Path:
    """Write ``data`` (made JSON-safe by :func:`json_safe`) to ``path`` as indented JSON, creating
    the parent folders; returns the path."""
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(json_safe(data), indent=2, allow_nan=False) + "\n")
    return out


def library_versions() -> dict[str, str | None]:
    """Installed versions of :data:`LIBRARIES` (None where not installed)."""
    out: dict[str, str | None] = {}
    for name in LIBRARIES:
        try:
            out[name] = importlib.metadata.version(name)
        except importlib.metadata.PackageNotFoundError:
            out[name] = None
    return out


def write_results(
    folder: str | Path,
    *,
    trajectory: Trajectory,
    report: VerificationReport,
    plan_dict: Mapping[str, Any],
    joint_names: Sequence[str],
    light_directions_camera: ArrayLike,
    image_pattern: str,
    figures: Mapping[str, Callable[[], bytes]] | None = None,
    writers: Sequence[Callable[[Path], Sequence[Path]]] = (),
    overwrite: bool = False,
    csv_rate_hz: float = 100.0,
) -> list[Path]:
    """Write a verified plan into ``folder`` (the output policy of the module docstring) and return
    the paths written.

    Files: ``trajectory.csv`` (:meth:`Trajectory.to_csv` at ``csv_rate_hz`` plus the boundaries),
    ``plan.json`` (``plan_dict`` plus the verification report, the trajectory's timing, library
    versions and the creation time), ``lights.lp`` (one line per capture, in capture order, names
    from ``image_pattern.format(index=i)``) and ``<name>.png`` for each of ``figures``, the PNG bytes
    each callable returns; then the manifest. The figures are asked for last, so that one drawn in
    another process meanwhile (:mod:`optlight.viz.drawing`) is not waited for before the rest.

    Args:
        light_directions_camera: (M, 3) unit vectors from the object towards the light at each capture,
            in the OpenCV camera frame (e.g. ``camera.to_camera_frame((a − O) / b)``).
        writers: callables that write further files (figures, preview, report) into the folder they
            are given and return the paths they wrote; they run before plan.json is written, so the
            folder appears with all of them or not at all.
        overwrite: update a folder optlight filled before (only the files its manifest lists).

    Raises:
        VerificationError: the report failed; nothing is written.
        UsageError: ``folder`` may not receive the results (:func:`check_output_folder`).
        ValueError, TypeError: bad inputs, data JSON cannot hold; raised before anything is written.
    """
    folder = Path(folder)
    if not report.passed:
        raise VerificationError(
            f"refusing to write {folder}: the plan failed verification\n{report.summary()}", report
        )
    directions = np.asarray(light_directions_camera, float)
    captures = trajectory.capture_times
    if directions.shape != (captures.size, 3):
        raise ValueError(
            f"expected ({captures.size}, 3) light directions, one per capture, got {directions.shape}"
        )
    norms = np.linalg.norm(directions, axis=1)
    if not np.allclose(norms, 1.0, atol=1e-6):
        raise ValueError(
            f"light directions must be unit vectors (norms {norms.min():.6g} … {norms.max():.6g})"
        )
    names = image_names(image_pattern, captures.size)
    clash = sorted(set(plan_dict) & set(RESERVED_KEYS))
    if clash:
        raise ValueError(f"plan_dict may not use the keys {clash}: write_results fills them")
    for name in figures or {}:
        if not name or Path(name).name != name or name.startswith("."):
            raise ValueError(f"figure name {name!r} must be a plain file stem")

    def plan_text(files: list[str]) -> str:
        return json.dumps({**plan, "files": files}, indent=2, allow_nan=False) + "\n"

    plan = {
        **json_safe(dict(plan_dict)),
        "verification": report.to_dict(),
        "timing": json_safe(
            {
                "duration_s": trajectory.duration,
                "capture_times_s": captures,
                "landmark_intervals_s": trajectory.landmark_intervals,
                "segment_times_s": trajectory.segment_times,
                "joint_names": list(joint_names),
                "csv_rate_hz": csv_rate_hz,
            }
        ),
        "versions": library_versions(),
        "created_utc": datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds"),
    }
    plan_text([])  # fails here, before anything is written, when plan_dict holds non-JSON data

    def write(staging: Path) -> list[Path]:
        files = ["trajectory.csv", "plan.json", "lights.lp", *(f"{n}.png" for n in figures or {})]
        trajectory.to_csv(staging / "trajectory.csv", joint_names, rate_hz=csv_rate_hz)
        (staging / "lights.lp").write_text(lp_text(names, lp_direction(directions)))
        for writer in writers:
            files += [str(Path(p).relative_to(staging)) for p in writer(staging)]
        interrupts.reached("figures")
        for name, png in (figures or {}).items():
            (staging / f"{name}.png").write_bytes(png())
        (staging / "plan.json").write_text(plan_text(files))
        return [staging / f for f in files]

    return write_folder(folder, write, overwrite=overwrite)


# --------------------------------------------------------------------------------------------
# The output policy
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class OutputTarget:
    """Where an output goes, as :func:`check_output_folder` / :func:`check_output_file` found it.

    ``path`` the folder or file; ``anchor`` the existing folder the staging folder or temporary file
    goes in (the folder itself when it exists, else its nearest existing ancestor, so nothing is
    created outside it before the final rename); ``exists`` whether ``path`` exists; ``previous``
    the files a folder's manifest lists (those ``overwrite`` may replace or remove).
    """

    path: Path
    anchor: Path
    exists: bool
    previous: tuple[str, ...] = ()


def check_output_folder(
    folder: str | Path,
    *,
    overwrite: bool = False,
    option: str = "folder",
    force: str = "overwrite=True",
    resume: str | None = None,
) -> OutputTarget:
    """Whether ``folder`` may receive an output folder (module docstring), and where to stage it.

    ``option`` names the folder in errors (``--out`` on the command line), ``force`` what the
    caller passes to allow replacing an earlier output; ``resume`` the kind of output in rounds the
    caller continues (an earlier output whose manifest names that kind is updated as with
    ``overwrite``). Raises :class:`UsageError` for an existing
    file or broken link, a non-empty folder without a valid manifest, an earlier output without
    ``overwrite``, and a location where nothing can be written (tried by creating and removing a
    staging folder there); :class:`OutputError` when another run is writing the folder (its lock,
    :mod:`optlight.locks`, kept from here to the end of a command). Writes nothing that stays.
    """
    path = Path(folder)
    locks.acquire(path)
    try:
        return _check_output_folder(path, overwrite, option, force, resume)
    finally:
        locks.release(path)


def _check_output_folder(
    path: Path, overwrite: bool, option: str, force: str, resume: str | None
) -> OutputTarget:
    if path.is_symlink() and not path.exists():
        raise UsageError(option, f"{path} is a broken symbolic link; give a new or empty folder")
    if not path.exists():
        anchor = _existing_ancestor(path, option)
        _probe(anchor, option)
        return OutputTarget(path, anchor, exists=False)
    if not path.is_dir():
        raise UsageError(
            option, f"{path} is an existing file; optlight writes a folder there: give a new or empty folder"
        )
    try:
        entries = list(path.iterdir())
    except OSError as e:
        raise UsageError(option, f"cannot read the folder {path} ({e.strerror})") from None
    previous: tuple[str, ...] = ()
    if entries:
        listed = _read_manifest(path)
        if listed is None:
            raise UsageError(
                option,
                f"{path} is not empty and holds files optlight did not write; give a new or empty folder "
                "(optlight never replaces files it did not write)",
            )
        if not overwrite and (resume is None or _manifest_resume(path) != resume):
            raise UsageError(
                option,
                f"{path} holds the output of an earlier optlight run; pass {force} to replace it "
                "(files you added there are kept)",
            )
        previous = listed
    _probe(path, option)
    return OutputTarget(path, path, exists=True, previous=previous)


def write_folder(
    folder: str | Path,
    write: Callable[[Path], Sequence[Path]],
    *,
    overwrite: bool = False,
    option: str = "folder",
    force: str = "overwrite=True",
    resume: str | None = None,
    resumable: str | None = None,
) -> list[Path]:
    """Fill ``folder`` with the files ``write(staging)`` writes into the staging folder it is given
    (it returns their paths), following the output policy; returns the paths in ``folder``.
    ``resume``: as for :func:`check_output_folder`; ``resumable``: the kind of output in rounds this
    one is, recorded in the manifest so that the next round may continue it (None: a finished output).

    The staging folder is removed when ``write`` raises or Ctrl-C arrives before the final renames;
    those run with Ctrl-C deferred. Raises what :func:`check_output_folder` raises,
    :class:`UsageError` (nothing changed) when a file to write exists in the folder without being
    listed in its manifest (it appeared after the check), and :class:`OutputError` naming the
    folder and the cause when the system refuses a write (a full disk, a file size limit).
    """
    locks.acquire(folder)  # held until the output is in place
    try:
        target = check_output_folder(folder, overwrite=overwrite, option=option, force=force, resume=resume)
    except BaseException:
        locks.release(folder)
        raise
    staging = target.anchor / f"{STAGING_PREFIX}{uuid.uuid4().hex[:12]}"
    moving = False
    try:
        with interrupts.deferred():  # created, then removed by the finally below: never left behind
            staging.mkdir()
        interrupts.reached("staging-created")
        files = [PurePosixPath(Path(p).relative_to(staging).as_posix()) for p in write(staging)]
        names = sorted({str(f) for f in files})
        manifest: dict[str, Any] = {"written_by": f"optlight {_version()}", "files": names}
        if resumable is not None:
            manifest["resume"] = resumable
        (staging / MANIFEST).write_text(json.dumps(manifest, indent=1) + "\n")
        interrupts.check()  # an interrupt a library swallowed while writing
        interrupts.reached("staging-written")
        with interrupts.deferred():
            interrupts.reached("renames")  # held back until the output is in place
            moving = True
            _move_into_place(staging, target, names, option)
    except OSError as e:
        partial = "some of its files may be the new output's" if moving and target.exists else "nothing was written"
        raise _write_error(target.path, e, staging, partial) from None
    finally:
        shutil.rmtree(staging, ignore_errors=True)  # gone already when renamed into place
        locks.release(folder)
    return [target.path / f for f in files]


def check_output_file(
    path: str | Path,
    *,
    overwrite: bool = False,
    option: str = "file",
    force: str = "overwrite=True",
    ours: Callable[[Path], bool] | None = None,
) -> OutputTarget:
    """Whether an output file may be written at ``path``: an existing file only with ``overwrite``,
    and then only when ``ours(path)`` says optlight wrote it (when given), never a folder; the nearest
    existing folder above it must be writable. Raises :class:`UsageError`, and :class:`OutputError`
    when another run is writing the file (as :func:`check_output_folder`)."""
    out = Path(path)
    locks.acquire(out)
    try:
        return _check_output_file(out, overwrite, option, force, ours)
    finally:
        locks.release(out)


def _check_output_file(
    out: Path, overwrite: bool, option: str, force: str, ours: Callable[[Path], bool] | None
) -> OutputTarget:
    if out.is_dir():
        raise UsageError(option, f"{out} is a folder; give the path of the file to write")
    exists = out.exists() or out.is_symlink()
    if exists and not overwrite:
        raise UsageError(option, f"{out} exists; pass {force} to replace it")
    if exists and ours is not None and (out.is_symlink() or not ours(out)):
        raise UsageError(
            option, f"{out} exists and optlight did not write it; {force} replaces only a file optlight wrote"
        )
    anchor = _existing_ancestor(out, option)
    _probe(anchor, option)
    return OutputTarget(out, anchor, exists=exists)


def write_file(
    path: str | Path,
    write: Callable[[Path], object],
    *,
    overwrite: bool = False,
    option: str = "file",
    force: str = "overwrite=True",
    ours: Callable[[Path], bool] | None = None,
) -> Path:
    """Write one file through ``write(temporary)`` (the temporary path keeps ``path``'s suffix) and
    rename it to ``path`` (missing folders above it created then), following the output policy
    (``ours``: see :func:`check_output_file`)."""
    locks.acquire(path)  # held until the file is in place
    try:
        target = check_output_file(path, overwrite=overwrite, option=option, force=force, ours=ours)
    except BaseException:
        locks.release(path)
        raise
    out = target.path
    temporary = target.anchor / f"{STAGING_PREFIX}{uuid.uuid4().hex[:12]}{out.suffix}"
    try:
        write(temporary)
        interrupts.check()
        with interrupts.deferred():
            out.parent.mkdir(parents=True, exist_ok=True)
            os.replace(temporary, out)
    except OSError as e:
        raise _write_error(out, e, temporary) from None
    finally:
        temporary.unlink(missing_ok=True)
        locks.release(path)
    return out


@contextmanager
def writes_into(folder: Path, kept: str) -> Iterator[None]:
    """Writes into ``folder`` outside :func:`write_folder` (a batch's records and table, which a run
    adds as it goes): a write the system refuses is an :class:`OutputError` naming the folder, the
    cause and what is ``kept``."""
    try:
        yield
    except OSError as e:
        raise _write_error(folder, e, folder, kept) from None


def _write_error(path: Path, error: OSError, within: Path, done: str = "nothing was written") -> OutputError:
    """The one-line error for ``error``, met while writing the output ``path`` through ``within``
    (the staging folder, the temporary file, the folder itself): the folder, the cause, the file it
    was writing (relative to ``within``), and what was ``done``."""
    cause = error.strerror or str(error)
    if error.errno in WRITE_FAILURES:
        cause = f"{WRITE_FAILURES[error.errno]} ({cause})"
    if error.filename:
        name = Path(os.fsdecode(error.filename))
        cause += f" at {name.relative_to(within) if name.is_relative_to(within) and name != within else name}"
    return OutputError(f"cannot write {path}: {cause}; {done}")


def _existing_ancestor(path: Path, option: str) -> Path:
    """The nearest existing folder at or above ``path``'s parent; a file there is refused."""
    anchor = path.absolute().parent
    while not anchor.exists():
        anchor = anchor.parent
    if not anchor.is_dir():
        raise UsageError(option, f"{anchor} is a file, so {path} cannot be created")
    return anchor


def _probe(folder: Path, option: str) -> None:
    """Refuse a folder where optlight cannot create (and remove) a staging folder."""
    probe = folder / f"{STAGING_PREFIX}probe-{uuid.uuid4().hex[:12]}"
    try:
        with interrupts.deferred():  # never left behind
            probe.mkdir()
            probe.rmdir()
    except OSError as e:
        raise UsageError(option, f"cannot write in {folder} ({e.strerror or e})") from None


def _read_manifest(folder: Path) -> tuple[str, ...] | None:
    """The files the folder's manifest lists, or None when it has no valid manifest (a listed path
    must be relative and stay inside the folder)."""
    try:
        data = json.loads((folder / MANIFEST).read_text())
    except (OSError, ValueError):
        return None
    files = data.get("files") if isinstance(data, dict) else None
    if not isinstance(files, list) or not all(isinstance(f, str) and f for f in files):
        return None
    for f in files:
        p = PurePosixPath(f)
        if p.is_absolute() or ".." in p.parts or str(p) == MANIFEST or "\\" in f:
            return None
    return tuple(files)


def _manifest_resume(folder: Path) -> str | None:
    """The kind of output in rounds the folder's manifest says may be continued, or None."""
    try:
        data = json.loads((folder / MANIFEST).read_text())
    except (OSError, ValueError):
        return None
    kind = data.get("resume") if isinstance(data, dict) else None
    return kind if isinstance(kind, str) else None


def _move_into_place(staging: Path, target: OutputTarget, names: Sequence[str], option: str) -> None:
    """Rename the staged output into place: the staging folder itself when the folder is new, else
    each file into the folder (then remove the files of the earlier output that the new one does not
    have), the manifest last."""
    folder = target.path
    if not target.exists:
        folder.parent.mkdir(parents=True, exist_ok=True)
        os.rename(staging, folder)
        return
    previous = set(target.previous)
    for name in names:
        dest = folder / name
        if (dest.exists() or dest.is_symlink()) and name not in previous:
            raise UsageError(
                option, f"{dest} appeared and was not written by optlight; move it away (nothing was changed)"
            )
    for name in names:
        dest = folder / name
        dest.parent.mkdir(parents=True, exist_ok=True)
        os.replace(staging / name, dest)
    for name in sorted(previous - set(names)):
        old = folder / name
        if old.is_file() or old.is_symlink():
            old.unlink()
    os.replace(staging / MANIFEST, folder / MANIFEST)


def _version() -> str:
    try:
        return importlib.metadata.version("optlight")
    except importlib.metadata.PackageNotFoundError:
        return "unknown"
