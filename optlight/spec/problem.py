"""The whole problem: one :class:`Problem` made of the sections, and its plain-data form."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from optlight.spec.environment import EnvironmentSpec, ViewSpec
from optlight.spec.keys import key, section
from optlight.spec.landmarks import LandmarksSpec, LightSetSpec
from optlight.spec.loop import LoopSpec, WorldSpec
from optlight.spec.objective import ObjectiveSpec
from optlight.spec.scene import CameraSpec, LightSpec, LightSphereSpec, ObjectSpec, RobotSpec
from optlight.spec.trajectory import SolverSpec, TrajectorySpec


@dataclass(frozen=True)
class Problem:
    """A whole light-positioning problem."""

    description: str = key("", "one line that says what the problem is")
    object: ObjectSpec = section(ObjectSpec, "the observed object")
    camera: CameraSpec = section(CameraSpec, "the fixed camera")
    light_sphere: LightSphereSpec = section(LightSphereSpec, "where the light may be")
    light: LightSpec = section(LightSpec, "the light and image model")
    robot: RobotSpec = section(RobotSpec, "the robot carrying the light")
    objective: ObjectiveSpec = section(ObjectiveSpec, "what a good image is")
    landmarks: LandmarksSpec = section(LandmarksSpec, "the landmark search")
    trajectory: TrajectorySpec = section(TrajectorySpec, "path, timing and export")
    solver: SolverSpec = section(SolverSpec, "numerical settings")
    environment: EnvironmentSpec = section(EnvironmentSpec, "obstacles, self-collision, the camera's view")
    lightset: LightSetSpec = section(LightSetSpec, "lights designed as a set (photometric stereo, RTI, grid)")
    view: ViewSpec = section(ViewSpec, "the camera's view of the object, kept clear of the robot and the light")
    world: WorldSpec = section(WorldSpec, "how the real scene differs from the model (the cameras in the loop)")
    loop: LoopSpec = section(LoopSpec, "the camera in the loop: capture, calibrate, re-plan")
    source: Path | None = field(default=None, compare=False, metadata={"internal": True})

    @property
    def name(self) -> str:
        """The problem's name: its file stem, or "inline"."""
        return self.source.stem if self.source else "inline"

    def resolve(self, relative: str) -> Path:
        """A path written in the problem file, made absolute against the file's folder."""
        path = Path(relative).expanduser()
        if path.is_absolute() or self.source is None:
            return path
        return (self.source.parent / path).resolve()

    def to_dict(self) -> dict[str, Any]:
        """The problem as plain data (for plan.json): every set key, defaults included."""
        return _to_plain(self)



def _to_plain(value: Any) -> Any:
    """A section (or value) as plain data: tables as dicts, lists as lists."""
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        # Unset (None) keys and empty lists are left out: TOML has no null, a missing key means its
        # default, and no key whose default is non-empty accepts an empty list.
        return {
            f.name: _to_plain(getattr(value, f.name))
            for f in dataclasses.fields(value)
            if not f.metadata.get("internal") and getattr(value, f.name) not in (None, ())
        }
    if isinstance(value, tuple):
        return [_to_plain(v) for v in value]
    return value
