"""Checks of a problem that involve several keys (zenith range, camera placement, per-kind
requirements, the real scene against the model), run once every key has its type and range."""

from __future__ import annotations

import numpy as np

from optlight.errors import ProblemError
from optlight.spec.problem import Problem
from optlight.spec.scene import ROBOT_NAMES
from optlight.spec.sizing import image_names


def check_consistency(p: Problem, file: str) -> None:
    """Checks that involve several keys: zenith range, camera placement, per-kind requirements.

    Checks that need a built object (the camera sees the object, the obstacles' geometry) run where
    it is built (:class:`optlight.setup.Setup`), with the same :class:`ProblemError`. The checks run
    in this order, so a file with several mistakes is refused for the same first one."""
    _check_scene(p, file)
    _check_objective(p, file)
    _check_robot(p, file)
    _check_trajectory(p, file)
    _check_light(p, file)
    _check_lightset(p, file)
    _check_world(p, file)


def _check_scene(p: Problem, file: str) -> None:
    """The zenith range is not empty, the camera is outside the light sphere and looks somewhere, the
    object is a mesh file that exists or a sphere inside the light sphere."""
    ls, cam, obj = p.light_sphere, p.camera, p.object
    if ls.zenith_min_deg >= ls.zenith_max_deg:
        raise ProblemError(
            file,
            "light_sphere.zenith_max_deg",
            f"a value > zenith_min_deg ({ls.zenith_min_deg:g})",
            ls.zenith_max_deg,
        )
    centre = np.asarray(obj.center_m)
    eye = np.asarray(cam.position_m)
    dist = float(np.linalg.norm(eye - centre))
    if dist <= ls.radius_m:
        raise ProblemError(
            file,
            "camera.position_m",
            f"a camera outside the light sphere (distance to the object {dist:.3f} m > radius {ls.radius_m:g} m)",
            list(cam.position_m),
        )
    target = np.asarray(cam.look_at_m) if cam.look_at_m is not None else centre
    forward = target - eye
    if np.linalg.norm(forward) < 1e-9:
        raise ProblemError(
            file, "camera.look_at_m", "a point different from the camera position", list(target)
        )
    if obj.kind == "mesh" and obj.path is None:
        raise ProblemError(file, "object.path", "a mesh file path (object.kind = 'mesh')")
    if obj.kind == "mesh" and obj.path is not None and not p.resolve(obj.path).is_file():
        raise ProblemError(file, "object.path", "an existing mesh file", obj.path)
    if obj.kind == "sphere" and obj.radius_m >= ls.radius_m:
        raise ProblemError(
            file,
            "object.radius_m",
            f"a sphere smaller than the light sphere (< {ls.radius_m:g} m)",
            obj.radius_m,
        )


def _check_objective(p: Problem, file: str) -> None:
    """The reference has what its kind needs (an image file, ``objective.bins`` bins with a positive
    sum); mean and contrast terms have a target."""
    ref = p.objective.reference
    if ref.kind == "image":
        if ref.image is None:
            raise ProblemError(file, "objective.reference.image", "an image path (reference.kind = 'image')")
        for name in ("image", "mask"):
            rel = getattr(ref, name)
            if rel is not None and not p.resolve(rel).is_file():
                raise ProblemError(file, f"objective.reference.{name}", "an existing PNG or NPY file", rel)
    if ref.kind == "bins":
        if ref.bins is None or len(ref.bins) != p.objective.bins:
            raise ProblemError(
                file,
                "objective.reference.bins",
                f"{p.objective.bins} non-negative numbers (objective.bins)",
                ref.bins,
            )
        if sum(ref.bins) <= 0:
            raise ProblemError(file, "objective.reference.bins", "bins with a positive sum", ref.bins)
    for i, term in enumerate(p.objective.terms):
        if term.kind in ("mean", "contrast") and term.target is None:
            raise ProblemError(file, f"objective.terms[{i}].target", f"a target value (kind = '{term.kind}')")


def _check_robot(p: Problem, file: str) -> None:
    """A built-in robot by name, or a URDF file that exists with its flange frame named."""
    if p.robot.urdf is None and p.robot.name not in ROBOT_NAMES:
        raise ProblemError(
            file,
            "robot.name",
            f"one of {', '.join(ROBOT_NAMES)} (or set robot.urdf and robot.frame)",
            p.robot.name,
        )
    if p.robot.urdf is not None:
        if not p.resolve(p.robot.urdf).is_file():
            raise ProblemError(file, "robot.urdf", "an existing URDF file", p.robot.urdf)
        if p.robot.frame is None:
            raise ProblemError(file, "robot.frame", "the flange frame name (robot.urdf is set)")


def _check_trajectory(p: Problem, file: str) -> None:
    """Image names that are distinct file names, flying captures timed jerk-limited, a settle time
    shorter than the dwell and, when stopping, an exposure within the dwell."""
    try:
        image_names(p.trajectory.image_pattern, p.landmarks.count)
    except ValueError as e:
        raise ProblemError(
            file,
            "trajectory.image_pattern",
            f'distinct file names from {{index}}, e.g. "img_{{index:03d}}.png" ({e})',
            p.trajectory.image_pattern,
        ) from None
    traj = p.trajectory
    if traj.capture == "flying" and traj.timing != "jerk_limited":
        raise ProblemError(
            file,
            "trajectory.capture",
            f'"stop" with trajectory.timing = "{traj.timing}" (flying captures are timed jerk-limited)',
            traj.capture,
        )
    if traj.settle_s >= traj.dwell_s:
        raise ProblemError(
            file,
            "trajectory.settle_s",
            f"a settle time shorter than the dwell (trajectory.dwell_s = {traj.dwell_s:g} s)",
            traj.settle_s,
        )
    if traj.capture == "stop" and traj.settle_s + traj.exposure_s > traj.dwell_s:
        raise ProblemError(
            file,
            "trajectory.exposure_s",
            f"an exposure that ends within the dwell (≤ dwell_s − settle_s = {traj.dwell_s - traj.settle_s:g} s)",
            traj.exposure_s,
        )


def _check_light(p: Problem, file: str) -> None:
    """The light's housing fits inside the light sphere."""
    ls, light = p.light_sphere, p.light
    if light.housing_radius_m >= ls.radius_m:
        raise ProblemError(
            file,
            "light.housing_radius_m",
            f"a housing smaller than the light sphere (< light_sphere.radius_m = {ls.radius_m:g} m)",
            light.housing_radius_m,
        )
    if light.housing == "cylinder" and light.housing_length_m >= ls.radius_m:
        raise ProblemError(
            file,
            "light.housing_length_m",
            f"a housing shorter than the light sphere radius (< {ls.radius_m:g} m)",
            light.housing_length_m,
        )


def _check_lightset(p: Problem, file: str) -> None:
    """Light counts per kind, one grid source, grid angles in range, the grid file present."""
    ls = p.lightset
    least = {"photometric_stereo": 3, "rti": 2}.get(ls.kind)
    if least is not None and ls.count < least:
        raise ProblemError(
            file, "lightset.count", f"at least {least} lights (lightset.kind = '{ls.kind}')", ls.count
        )
    if ls.grid_file is not None and ls.grid_deg is not None:
        raise ProblemError(file, "lightset.grid_deg", "either grid_deg or grid_file, not both", "both set")
    if ls.grid_file is not None and not p.resolve(ls.grid_file).is_file():
        raise ProblemError(file, "lightset.grid_file", "an existing CSV file", ls.grid_file)
    for i, (_, elevation) in enumerate(ls.grid_deg or ()):
        if not -90.0 <= elevation <= 90.0:
            raise ProblemError(file, f"lightset.grid_deg[{i}][1]", "an elevation in [−90, 90] deg", elevation)


def _check_world(p: Problem, file: str) -> None:
    """The real light (its radius, its offset from the modelled one) fits inside the light sphere, a
    spot beam is a point light, the sensor noise does not drown the captures."""
    ls, light = p.light_sphere, p.light
    if p.world.light_profile == "spot" and p.world.light_radius_m > 0:
        raise ProblemError(
            file, "world.light_radius_m", "0 for a spot beam (light_profile = 'spot' is a point light)", p.world.light_radius_m
        )
    if p.world.light_radius_m >= ls.radius_m:
        raise ProblemError(
            file, "world.light_radius_m", f"a light smaller than the light sphere (< {ls.radius_m:g} m)", p.world.light_radius_m
        )
    offset = float(np.linalg.norm(p.world.light_offset_m))
    if offset >= ls.radius_m:
        raise ProblemError(
            file,
            "world.light_offset_m",
            f"an offset shorter than the light sphere's radius ({offset:.3g} m ≥ {ls.radius_m:g} m puts "
            "the real light anywhere, even behind the object)",
            list(p.world.light_offset_m),
        )
    lamp = float(np.linalg.norm(p.world.lamp_offset_m))
    if lamp >= ls.radius_m:
        raise ProblemError(
            file,
            "world.lamp_offset_m",
            f"an offset shorter than the light sphere's radius ({lamp:.3g} m ≥ {ls.radius_m:g} m)",
            list(p.world.lamp_offset_m),
        )
    if p.world.noise_std > light.saturation:
        raise ProblemError(
            file,
            "world.noise_std",
            f"a noise σ ≤ light.saturation = {light.saturation:g} (more drowns every capture)",
            p.world.noise_std,
        )
