"""Random, sensible cells: seeded problems a new user could write, for the tests and the benchmark.

``random_cell(seed, folder)`` draws one cell and returns it as a :class:`RandomCell`: the problem as
plain data (what a problem file holds), its :class:`~optlight.spec.Problem`, and the labels of what
was drawn (robot, object, task, environment), by which the benchmark groups its results. The same
seed gives the same cell. What is drawn:

- the robot: every built-in arm (:data:`~optlight.spec.ROBOT_NAMES`), or one of their URDFs loaded
  as a user URDF (``[robot] urdf``, the limits' middle as reference, the hand joints free);
- the object: the procedural face, a sphere, or a mesh (a capsule or a rounded box written as OBJ
  into ``folder``), its centre O in front of the base at 0.45–0.6 m (scaled by the arm's reach,
  :data:`REACH_M`, for arms shorter than the Panda), 0.25–0.5 m above the base (scaled likewise);
- the camera, 0.6–1.0 m from O (scaled), on the robot's side of the object and beside the base,
  never behind it: its distance along the base → object line from the base is at least
  :data:`CAMERA_AHEAD_M`, and it stands at least :data:`CAMERA_BESIDE_M` (scaled) off the robot's
  vertical axis; 0–30° above O's height; its field of view just holds the object;
- the light sphere: radius between the object's bound plus the housing and the camera distance less
  0.15 m, cap from 0 (or 10–20°) to 40–70°;
- the task: histogram landmarks (azimuth or free), or a light set (photometric stereo, RTI, a grid
  of directions round the camera axis), with ``[landmarks] allow_partial`` (a landmark or light the
  arm cannot reach clear is dropped with a warning, the rest planned);
- the environment, in half the cells: a table at the base or just below it (0–3 cm), the camera
  body and its stand, and a wall behind the robot in half of those.

Lengths in metres, angles in degrees (problem-file units).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from optlight.spec import ROBOT_NAMES, Problem, problem_from_dict

#: Published reach of each arm (m), from the makers' datasheets: Franka Panda 855 mm, UR3/5/10
#: 500/850/1300 mm, xArm7 700 mm, Kinova JACO² 6-DOF 985 mm, Unitree Z1 740 mm.
REACH_M: dict[str, float] = {
    "panda": 0.855,
    "ur3": 0.50,
    "ur5": 0.85,
    "ur10": 1.30,
    "xarm7": 0.70,
    "kinova": 0.985,
    "z1": 0.74,
}
#: The arm the cell's distances are drawn for (the Panda's reach); shorter arms scale them down.
REFERENCE_REACH_M = 0.855
#: Smallest scale of the cell's distances (a very short arm still holds a head-sized face).
MIN_SCALE = 0.6
#: URDFs (example-robot-data) and flange frames of the user-URDF cells.
USER_URDFS: dict[str, tuple[str, str]] = {
    "panda": ("panda_description/urdf/panda.urdf", "panda_hand_tcp"),
    "ur5": ("ur_description/urdf/ur5_robot.urdf", "tool0"),
    "xarm7": ("xarm_description/urdf/xarm7.urdf", "link_eef"),
}
#: The camera's distance from the base along the base → object line is at least this (m): it is
#: not behind the robot.
CAMERA_AHEAD_M = 0.05
#: The camera stands at least this far off the robot's vertical axis (m; scaled with the cell).
CAMERA_BESIDE_M = 0.30
#: Kinds drawn, with their labels in :attr:`RandomCell.labels`.
OBJECTS = ("face", "sphere", "mesh")
TASKS = ("landmarks", "photometric_stereo", "rti", "grid")
#: Camera image side (px): small, so that a hundred cells solve in reasonable time.
IMAGE_PX = 128
#: Light housing length (m) of [light] (the default), which the light sphere must leave room for.
HOUSING_M = 0.06


@dataclass(frozen=True)
class RandomCell:
    """One drawn cell: ``seed``; ``data`` the problem as plain data (a problem file's tables);
    ``labels`` what was drawn (``robot``, ``object``, ``task``, ``environment``); ``object_radius``
    the object's bounding radius around O (m) used in the drawing."""

    seed: int
    data: dict[str, Any]
    labels: dict[str, str]
    object_radius: float

    @property
    def problem(self) -> Problem:
        """The validated problem (:func:`~optlight.spec.problem_from_dict`)."""
        return problem_from_dict(self.data)

    @property
    def name(self) -> str:
        """``cell<seed>-<robot>-<object>-<task>[-env]``."""
        env = "-env" if self.labels["environment"] != "none" else ""
        return f"cell{self.seed}-{self.labels['robot']}-{self.labels['object']}-{self.labels['task']}{env}"


def _unit(azimuth: float, elevation: float) -> np.ndarray:
    """Unit vector at ``azimuth`` about +z from +x and ``elevation`` above the xy-plane (rad)."""
    return np.array(
        [math.cos(elevation) * math.cos(azimuth), math.cos(elevation) * math.sin(azimuth), math.sin(elevation)]
    )


def _robot(rng: np.random.Generator) -> tuple[dict[str, Any], str, float]:
    """The ``[robot]`` table, its label and the arm's reach (m): a built-in arm, or (one in eight)
    an arm's URDF loaded as a user URDF."""
    if rng.random() < 1 / 8:
        from optlight.robot.catalogue import example_robot_data_dir

        name = str(rng.choice(sorted(USER_URDFS)))
        urdf, frame = USER_URDFS[name]
        path = example_robot_data_dir() / "example-robot-data" / "robots" / urdf
        return {"name": f"user_{name}", "urdf": str(path), "frame": frame}, f"urdf:{name}", REACH_M[name]
    name = str(rng.choice(ROBOT_NAMES))
    return {"name": name}, name, REACH_M[name]


def _object(rng: np.random.Generator, scale: float, folder: Path | None, seed: int) -> tuple[dict[str, Any], float]:
    """The ``[object]`` table without its centre, and its bounding radius around O (m)."""
    kind = str(rng.choice(OBJECTS if folder is not None else OBJECTS[:2]))
    if kind == "face":
        height = float(rng.uniform(0.18, 0.24)) * scale
        # the face spans ±0.5 height up and ±0.4 height across, and its relief (the nose, 0.028 m
        # at any height) stands out: its farthest point from O is within 0.6 height + 0.03 m
        return {"kind": "face", "face": {"height_m": round(height, 4)}}, 0.6 * height + 0.03
    if kind == "sphere":
        radius = round(float(rng.uniform(0.05, 0.11)) * scale, 4)
        return {"kind": "sphere", "radius_m": radius, "albedo": 0.8}, radius
    import trimesh

    assert folder is not None
    if rng.random() < 0.5:
        radius, height = float(rng.uniform(0.04, 0.07)), float(rng.uniform(0.06, 0.14))
        mesh = trimesh.creation.capsule(height=height, radius=radius, count=[24, 24])
    else:
        extents = rng.uniform(0.08, 0.16, size=3)
        mesh = trimesh.creation.box(extents=extents)
        mesh = mesh.subdivide().subdivide()
    mesh.apply_transform(trimesh.transformations.random_rotation_matrix(rng.random(3)))
    mesh.apply_scale(scale)
    mesh.apply_translation(-mesh.bounding_box.centroid)
    path = Path(folder) / f"cell{seed}_object.obj"
    path.parent.mkdir(parents=True, exist_ok=True)
    mesh.export(path)
    radius = float(np.max(np.linalg.norm(mesh.vertices, axis=1)))
    return {"kind": "mesh", "path": str(path), "albedo": 0.8}, radius


def _task(rng: np.random.Generator, zenith_max: float) -> tuple[dict[str, Any], str]:
    """The tables of the task and its label: histogram landmarks, or a light set."""
    task = str(rng.choice(TASKS))
    reference = {"kind": "light", "zenith_deg": round(float(rng.uniform(5.0, 0.6 * zenith_max)), 1),
                 "azimuth_deg": round(float(rng.uniform(0.0, 360.0)), 1)}
    tables: dict[str, Any] = {
        "objective": {"terms": [{"kind": "histogram", "distance": "emd2"}], "reference": reference}
    }
    if task == "landmarks":
        mode = str(rng.choice(("azimuth", "free")))
        # as a user whose arm reaches part of the cap would: the landmarks it reaches, the rest dropped
        tables["landmarks"] = {
            "mode": mode,
            "count": int(rng.integers(6, 25 if mode == "azimuth" else 13)),
            "allow_partial": True,
        }
        return tables, task
    # a set's lights are captured in a joint-space tour; far-apart lights leave no arcs to follow
    tables["trajectory"] = {"order": "tour", "path": "free"}
    tables["landmarks"] = {"allow_partial": True}
    if task == "photometric_stereo":
        tables["lightset"] = {"kind": task, "count": int(rng.integers(4, 11)), "starts": 2}
    elif task == "rti":
        tables["lightset"] = {"kind": task, "count": int(rng.integers(8, 21)), "starts": 2}
    else:
        count = int(rng.integers(6, 13))
        reach = 0.8 * zenith_max
        pairs = rng.uniform(-reach, reach, size=(count, 2))
        tables["lightset"] = {"kind": "grid", "grid_deg": [[round(float(a), 1), round(float(e), 1)] for a, e in pairs]}
    return tables, task


def random_cell(seed: int, folder: Path | str | None = None) -> RandomCell:
    """The sensible cell of ``seed`` (module docstring). ``folder``: where a mesh object is written
    (without one, the object is a face or a sphere)."""
    rng = np.random.default_rng(seed)
    robot, robot_label, reach = _robot(rng)
    scale = min(1.0, max(MIN_SCALE, reach / REFERENCE_REACH_M))
    obj, obj_radius = _object(rng, scale, Path(folder) if folder is not None else None, seed)

    # O in front of the base (+x turned by up to ±30°), above it
    heading = math.radians(float(rng.uniform(-30.0, 30.0)))
    forward = _unit(heading, 0.0)
    reach_out = float(rng.uniform(0.45, 0.60)) * scale
    height = float(rng.uniform(0.25, 0.50)) * scale
    center = reach_out * forward + np.array([0.0, 0.0, height])

    # the camera: on the robot's side of O, beside the base, not behind it
    distance = float(rng.uniform(0.6, 1.0)) * scale
    elevation = math.radians(float(rng.uniform(0.0, 30.0)))
    horizontal = distance * math.cos(elevation)
    # the angle β between O → base and O → camera (horizontal) with the camera ahead of the base:
    # reach_out − horizontal·cos β ≥ CAMERA_AHEAD_M, and off the base's axis by CAMERA_BESIDE_M
    # and |O + horizontal·(O → camera)| ≥ beside (the law of cosines)
    beside = CAMERA_BESIDE_M * scale
    cos_ahead = (reach_out - CAMERA_AHEAD_M) / horizontal
    cos_beside = (reach_out**2 + horizontal**2 - beside**2) / (2.0 * reach_out * horizontal)
    least = math.acos(max(-1.0, min(1.0, cos_ahead, cos_beside)))
    side = 1.0 if rng.random() < 0.5 else -1.0
    beta = float(rng.uniform(least, math.radians(90.0))) * side
    back = -forward
    turned = np.array(
        [back[0] * math.cos(beta) - back[1] * math.sin(beta), back[0] * math.sin(beta) + back[1] * math.cos(beta), 0.0]
    )
    eye = center + horizontal * turned + np.array([0.0, 0.0, distance * math.sin(elevation)])
    fov = math.degrees(2.0 * math.atan(1.3 * obj_radius / distance))

    zenith_max = float(rng.uniform(40.0, 70.0))
    zenith_min = 0.0 if rng.random() < 0.7 else float(rng.uniform(10.0, 20.0))
    radius_lo = obj_radius + HOUSING_M + 0.05
    radius_hi = max(radius_lo, min(0.45 * scale, distance - 0.15))
    light_radius = float(rng.uniform(radius_lo, radius_hi))

    data: dict[str, Any] = {
        "description": f"random cell {seed}",
        "object": {**obj, "center_m": [round(float(v), 4) for v in center]},
        "camera": {
            "position_m": [round(float(v), 4) for v in eye],
            "width": IMAGE_PX,
            "height": IMAGE_PX,
            "fov_deg": round(fov, 2),
        },
        "light_sphere": {
            "radius_m": round(light_radius, 4),
            "zenith_min_deg": round(zenith_min, 1),
            "zenith_max_deg": round(zenith_max, 1),
        },
        "robot": robot,
        "landmarks": {"resolution": IMAGE_PX},
    }
    tables, task = _task(rng, zenith_max)
    for name, table in tables.items():
        data[name] = {**data.get(name, {}), **table}

    environment = "none"
    if rng.random() < 0.5:
        table_height = -round(float(rng.uniform(0.0, 0.03)), 3)
        env: dict[str, Any] = {"enabled": True, "table_height_m": table_height, "camera_body": True}
        environment = "table"
        if rng.random() < 0.5:
            # a wall behind the base, across the base → object line
            wall = -float(rng.uniform(0.35, 0.5)) * forward
            env["boxes"] = [
                {
                    "name": "wall",
                    "center_m": [round(float(wall[0]), 4), round(float(wall[1]), 4), 0.6],
                    "size_m": [0.04, 1.6, 1.2],
                    "rpy_deg": [0.0, 0.0, round(math.degrees(heading), 2)],
                }
            ]
            environment = "table+wall"
        data["environment"] = env
    labels = {"robot": robot_label, "object": str(obj["kind"]), "task": task, "environment": environment}
    return RandomCell(seed, data, labels, obj_radius)


def to_toml(data: dict[str, Any]) -> str:
    """``data`` (a problem's tables: strings, numbers, booleans, lists of them, nested tables, lists
    of tables) as TOML text that :mod:`tomllib` reads back to ``data``, e.g. to keep a drawn cell as a
    problem file."""
    lines: list[str] = []

    def value(v: Any) -> str:
        if isinstance(v, bool):
            return "true" if v else "false"
        if isinstance(v, str):
            return '"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"'
        if isinstance(v, list):
            return "[" + ", ".join(value(x) for x in v) + "]"
        return repr(v)

    def table(path: str, d: dict[str, Any], header: str) -> None:
        scalars = {k: v for k, v in d.items() if not _is_table(v)}
        if header:
            lines.extend(["", header])
        lines.extend(f"{k} = {value(v)}" for k, v in scalars.items())
        for k, v in d.items():
            sub = f"{path}.{k}" if path else k
            if isinstance(v, dict):
                table(sub, v, f"[{sub}]")
            elif _is_table(v):
                for item in v:
                    table(sub, item, f"[[{sub}]]")

    table("", data, "")
    return "\n".join(lines).lstrip("\n") + "\n"


def _is_table(v: Any) -> bool:
    """A nested table, or a non-empty list of tables."""
    return isinstance(v, dict) or (isinstance(v, list) and bool(v) and all(isinstance(x, dict) for x in v))
