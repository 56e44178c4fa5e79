"""What a run of a problem will need, checked before the work: its image names, its memory and its
sampled trajectory's. Checks of this machine, not of the file: they run where the problem is built."""

from __future__ import annotations

import math

import numpy as np

from optlight.errors import ProblemError
from optlight.spec.problem import Problem


def image_names(pattern: str, count: int) -> list[str]:
    """``pattern.format(index=i)`` for i = 0 … count−1; names must be distinct and free of whitespace
    (lights.lp separates fields by spaces), and each a file name in the dataset's own folder (no path
    separator, no ``..``). Raises ValueError saying what is wrong."""
    try:
        names = [pattern.format(index=i) for i in range(count)]
    except (KeyError, IndexError, ValueError, AttributeError, TypeError) as e:
        raise ValueError(f"image pattern {pattern!r} must format with only {{index}} ({e!r})") from None
    if len(set(names)) != len(names):
        raise ValueError(f"image pattern {pattern!r} gives repeated names; use {{index}}")
    bad = [n for n in names if not n or any(c.isspace() for c in n)]
    if bad:
        raise ValueError(f"image names may not be empty or contain whitespace (.lp format): {bad[0]!r}")
    outside = [n for n in names if any(c in n for c in "/\\") or ".." in n or n.startswith("~")]
    if outside:
        raise ValueError(
            f"an image name is a file in the dataset's folder, without / \\ or ..: {outside[0]!r}"
        )
    return names


#: Peak memory of a solve: a fixed part (the libraries, the robot, the NLPs; ~250 MB over the
#: imports) plus a part per object pixel at the camera's resolution (rays, G-buffer, images). Whole
#: solves of the default problem grow by ~80 bytes per pixel at 128²–320² and by up to ~800 at
#: 256²–1024²; the constant keeps the larger (temporaries of the G-buffer's rays grow with the
#: image). The soft histogram adds almost nothing per pixel and bin: its NumPy kernel runs in chunks
#: of fixed size (~1 byte per pixel and bin, 32 → 128 bins at 320²).
#: Every image pixel is counted as an object pixel, since the object may fill the image.
MEMORY_BASE_BYTES = 600e6
MEMORY_BYTES_PER_PIXEL = 1200.0
#: Fraction of the available memory a run may plan to use (the rest: other processes, estimate error).
MEMORY_SAFETY = 0.8


def estimated_peak_memory(problem: Problem) -> float:
    """Bytes a solve of ``problem`` is expected to hold at its peak (see :data:`MEMORY_BASE_BYTES`):
    base + W·H·per pixel."""
    return MEMORY_BASE_BYTES + problem.camera.width * problem.camera.height * MEMORY_BYTES_PER_PIXEL


def available_memory() -> float | None:
    """Bytes of memory a new allocation can get without swapping: MemAvailable from /proc/meminfo
    (Linux), else the free physical pages (``os.sysconf``); None where neither is known."""
    import os

    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return float(line.split()[1]) * 1024.0
    except OSError:
        pass
    try:
        return float(os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE"))
    except (ValueError, OSError, AttributeError):
        return None


def check_memory(problem: Problem) -> None:
    """Raise :class:`ProblemError` (key ``camera.width``) when the solve's estimated peak memory
    (:func:`estimated_peak_memory`) exceeds :data:`MEMORY_SAFETY` of the memory available now;
    unchecked where that is unknown. A check of this machine, not of the file: it runs where the
    problem is built (:class:`optlight.setup.Setup`), not when the file is loaded, so a problem
    loaded on one machine can be solved on another with more memory."""
    available = available_memory()
    need = estimated_peak_memory(problem)
    if available is None or need <= MEMORY_SAFETY * available:
        return
    cam = problem.camera
    raise ProblemError(
        str(problem.source) if problem.source else "<inline>",
        "camera.width",
        f"a camera.width × camera.height image whose solve fits in memory: {cam.width} × {cam.height} "
        f"pixels with {problem.objective.bins} objective.bins needs about {need / 1e9:.1f} GB, "
        f"{available / 1e9:.1f} GB is available; lower camera.width and camera.height",
        cam.width,
    )


#: Bytes a sampled trajectory holds per sample and joint in its largest writer: the text of
#: joint_trajectory.yaml (~210 B per sample and joint measured with 7 joints; trajectory.csv's rows
#: ~175 B, the verification's arrays ~120 B, each one at a time).
SAMPLE_BYTES_PER_JOINT = 250.0


def planned_captures(problem: Problem) -> int:
    """The captures a plan of ``problem`` is planned with: ``[lightset] count`` for a designed set,
    the grid's length for a grid (``grid_deg``'s pairs, a ``grid_file``'s lines that are neither
    blank, comments nor its header; the 64 Yale B directions by default), else ``[landmarks] count``
    (landmarks that merge make fewer)."""
    ls = problem.lightset
    if ls.kind == "grid":
        if ls.grid_deg is not None:
            return len(ls.grid_deg)
        if ls.grid_file is None:
            return 64
        try:
            lines = problem.resolve(ls.grid_file).read_text().splitlines()
        except (OSError, UnicodeDecodeError):
            return 1  # the grid's reader names the file and the key
        return max(sum(1 for s in lines if s.strip() and not s.lstrip().startswith("#")) - 1, 1)
    return ls.count if ls.kind != "none" else problem.landmarks.count


def trajectory_samples_budget(problem: Problem, joints: int) -> float | None:
    """The most samples (:data:`SAMPLE_BYTES_PER_JOINT` × ``joints`` bytes each) the trajectory's
    writers can hold in :data:`MEMORY_SAFETY` of the memory available now, beside the solve's own
    (:func:`estimated_peak_memory`); None where the available memory is unknown."""
    available = available_memory()
    if available is None:
        return None
    free = MEMORY_SAFETY * available - estimated_peak_memory(problem)
    return max(free, 0.0) / (SAMPLE_BYTES_PER_JOINT * joints)


def sample_rate(problem: Problem) -> float:
    """Samples per second of the motion (Hz): ``[trajectory] rate_hz`` for the exports, at least 1 kHz
    for the verification."""
    return max(problem.trajectory.rate_hz, 1000.0)


def least_move_time(
    distance_m: float,
    reach_m: float,
    velocity: np.ndarray,
    acceleration: np.ndarray,
    jerk: np.ndarray | None,
) -> tuple[float, str]:
    """A lower bound (s) of the time of a rest-to-rest move that carries the light ``distance_m``, and
    the key of the limit that sets it (``robot.velocity_scale``, ``robot.acceleration_limit`` or
    ``robot.jerk_limit``).

    The light's speed is at most Σ_j |q̇_j| R (``reach_m`` = R ≥ the distance from any joint axis to
    the light), so d ≤ R Σ_j ∫|q̇_j| dt, and over a move of time T from rest to rest each joint
    travels ∫|q̇_j| dt ≤ v_j T, ≤ a_j T²/4 and, starting and ending with q̈ = 0 (jerk-limited
    timing), ≤ j_j T³/24. Hence T ≥ max(d / (R Σv), 2 √(d / (R Σa)), ∛(24 d / (R Σj)))."""
    x = distance_m / reach_m
    times = {
        "robot.velocity_scale": x / float(np.sum(velocity)),
        "robot.acceleration_limit": 2.0 * math.sqrt(x / float(np.sum(acceleration))),
    }
    if jerk is not None:
        times["robot.jerk_limit"] = (24.0 * x / float(np.sum(jerk))) ** (1.0 / 3.0)
    limit = max(times, key=lambda k: times[k])
    return times[limit], limit


def check_trajectory_size(
    problem: Problem,
    *,
    joints: int,
    reach_m: float,
    velocity: np.ndarray,
    acceleration: np.ndarray,
    jerk: np.ndarray,
    captures: int,
) -> None:
    """Raise :class:`ProblemError` when the sampled trajectory cannot fit in this machine's memory
    (:func:`trajectory_samples_budget`), by a lower estimate of its duration made before any work:
    ``captures`` dwells of ``dwell_s`` (none with flying captures) and ``captures − 1`` moves between captures at least
    ``[landmarks] distinct_deg`` apart on the light sphere, each at least :func:`least_move_time`
    under the robot's limits (``velocity`` already scaled by ``velocity_scale``). The refusal names the
    key that makes the trajectory too long (``rate_hz``, ``dwell_s`` or a motion limit) and the
    largest (or smallest) value this machine can do. Unchecked where the available memory is unknown.
    Like :func:`check_memory`, a check of this machine, run where the problem is built."""
    budget = trajectory_samples_budget(problem, joints)
    if budget is None:
        return
    traj, rate = problem.trajectory, sample_rate(problem)
    angle = math.radians(problem.landmarks.distinct_deg)
    distance = 2.0 * problem.light_sphere.radius_m * math.sin(angle / 2.0)
    jerk_used = jerk if traj.timing == "jerk_limited" else None
    move, limit = least_move_time(distance, reach_m, velocity, acceleration, jerk_used)
    moves = max(captures - 1, 0)
    dwell = captures * traj.dwell_s if traj.capture == "stop" else 0.0  # flying captures: no dwell
    duration = dwell + moves * move
    if duration * rate <= budget:
        return
    file = str(problem.source) if problem.source else "<inline>"
    need = duration * rate * SAMPLE_BYTES_PER_JOINT * joints
    why = (
        f"a trajectory of at least {duration:.3g} s ({captures} captures × dwell_s {traj.dwell_s:g} s, "
        f"{moves} moves of at least {move:.3g} s) sampled at {rate:g} Hz needs {need / 1e9:.3g} GB for "
        f"its {joints}-joint samples, {budget * SAMPLE_BYTES_PER_JOINT * joints / 1e9:.3g} GB is free here"
    )
    seconds = budget / rate  # the longest trajectory this machine can sample at this rate
    if traj.rate_hz > 1000.0 and duration * 1000.0 <= budget:
        expected = f"a value ≤ {budget / duration:.3g} Hz on this machine: {why}"
        raise ProblemError(file, "trajectory.rate_hz", expected, traj.rate_hz)
    if dwell >= duration - dwell or seconds <= dwell:
        if captures > 0 and seconds > moves * move:
            largest = (seconds - moves * move) / captures
            expected = f"a value ≤ {largest:.3g} s on this machine: {why}"
            raise ProblemError(file, "trajectory.dwell_s", expected, traj.dwell_s)
        raise ProblemError(file, "trajectory.dwell_s", f"a shorter dwell: {why}", traj.dwell_s)
    per_move = (seconds - dwell) / moves  # the time a move may take
    ratio = move / per_move  # > 1: how much faster the moves must be
    value: object
    if limit == "robot.velocity_scale":
        value, smallest = problem.robot.velocity_scale, problem.robot.velocity_scale * ratio
        expected = f"a value ≥ {smallest:.3g} on this machine: {why}"
    elif limit == "robot.acceleration_limit":
        value = problem.robot.acceleration_limit or float(np.max(acceleration))
        fastest = float(np.max(acceleration)) * ratio**2
        expected = (
            f"limits ≥ {ratio**2:.3g} × the present ones ({fastest:.3g} rad/s² on the fastest joint) "
            f"on this machine: {why}"
        )
    else:
        value = problem.robot.jerk_limit or float(np.max(jerk))
        fastest = float(np.max(jerk)) * ratio**3
        expected = (
            f"limits ≥ {ratio**3:.3g} × the present ones ({fastest:.3g} rad/s³ on the fastest joint) "
            f"on this machine: {why}"
        )
    raise ProblemError(file, limit, expected, value)


def check_trajectory_samples(problem: Problem, joints: int, duration: float, dwell: float) -> None:
    """Raise :class:`ProblemError` when a timed trajectory of ``duration`` s (``dwell`` s of them
    dwells) has more samples than this machine can hold (:func:`trajectory_samples_budget`): the
    check, on the trajectory itself, after its timing and before it is sampled, of what
    :func:`check_trajectory_size` estimated. Names ``rate_hz`` when a lower rate would do, else
    ``dwell_s`` or ``velocity_scale`` after the larger of the dwells and the motion."""
    budget = trajectory_samples_budget(problem, joints)
    rate = sample_rate(problem)
    if budget is None or duration * rate <= budget:
        return
    file = str(problem.source) if problem.source else "<inline>"
    traj = problem.trajectory
    per_sample = SAMPLE_BYTES_PER_JOINT * joints
    why = (
        f"the timed trajectory lasts {duration:.4g} s ({duration - dwell:.4g} s moving): "
        f"{duration * rate:.3g} samples at {rate:g} Hz need {duration * rate * per_sample / 1e9:.3g} GB, "
        f"{budget * per_sample / 1e9:.3g} GB is free here"
    )
    if traj.rate_hz > 1000.0 and duration * 1000.0 <= budget:
        expected = f"a value ≤ {budget / duration:.3g} Hz on this machine: {why}"
        raise ProblemError(file, "trajectory.rate_hz", expected, traj.rate_hz)
    if dwell >= duration - dwell:
        raise ProblemError(file, "trajectory.dwell_s", f"a shorter dwell: {why}", traj.dwell_s)
    raise ProblemError(
        file,
        "robot.velocity_scale",
        f"a faster motion (a larger velocity_scale, acceleration_limit or jerk_limit): {why}",
        problem.robot.velocity_scale,
    )
