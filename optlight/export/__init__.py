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
``light_dir_to_camera``), the light position in the world, the joint angles at the trigger and, from a
plan, the exposure (``exposure_start_s``, ``exposure_end_s``) and the blur the trajectory gives it
(``blur_deg``: the angle the light turns about the object's centre, ``blur_mm``: the distance it
travels; measured by :func:`optlight.verify.exposure_blur`). Flying captures
(``[trajectory] capture = "flying"``) have a dwell of zero length: the trigger is the instant the
light is at the landmark, the exposure centred on it; after a stop the exposure starts at the trigger.

Light directions: one frame for every file that holds them (captures.csv, lights.lp and the DiLiGenT
folder's ``light_directions.txt``): the unit vector from the object towards the light, x to the
right of the image, y towards its top, z towards the camera (:data:`LIGHT_FRAME`).
"""

from optlight.export.files import (
    EXPOSURE_COLUMNS,
    FOLLOW_JOINT_TRAJECTORY_GOAL,
    GOAL_TIME_TOLERANCE_S,
    JOINT_TRAJECTORY,
    LIGHT_DIRECTION_COLUMNS,
    LIGHT_FRAME,
    follow_joint_trajectory_goal_text,
    joint_trajectory_text,
    lp_direction,
    lp_text,
    read_joint_trajectory,
    write_captures,
    write_joint_trajectory,
    write_json,
)
from optlight.export.policy import (
    MANIFEST,
    STAGING_PREFIX,
    OutputTarget,
    check_output_file,
    check_output_folder,
    write_file,
    write_folder,
    writes_into,
)
from optlight.export.results import LIBRARIES, RESERVED_KEYS, library_versions, write_results

__all__ = [
    "FOLLOW_JOINT_TRAJECTORY_GOAL",
    "GOAL_TIME_TOLERANCE_S",
    "JOINT_TRAJECTORY",
    "LIBRARIES",
    "EXPOSURE_COLUMNS",
    "LIGHT_DIRECTION_COLUMNS",
    "LIGHT_FRAME",
    "MANIFEST",
    "OutputTarget",
    "RESERVED_KEYS",
    "STAGING_PREFIX",
    "check_output_file",
    "check_output_folder",
    "follow_joint_trajectory_goal_text",
    "joint_trajectory_text",
    "library_versions",
    "lp_direction",
    "lp_text",
    "read_joint_trajectory",
    "write_captures",
    "write_file",
    "write_folder",
    "write_joint_trajectory",
    "write_json",
    "write_results",
    "writes_into",
]
