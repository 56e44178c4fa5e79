"""The folder camera's round protocol (docs/design.md §11): with a real camera the loop runs in rounds,
one run of the command per round. Round i's plan is written to ``round_ii/`` of the acquisition
folder, its images named ``rii_000.png`` …; :class:`RoundFolders` finds the rounds whose images are
there and the first one awaiting them."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

from optlight.capture.folder import FolderCamera, read_captures_csv
from optlight.errors import UsageError
from optlight.jsondata import json_safe
from optlight.scene import Camera
from optlight.setup import Setup
from optlight.spec import Problem

#: The kind of output in rounds (:mod:`optlight.export`'s manifest) of an acquisition with the folder
#: camera: the same command continues it.
ROUNDS = "optlight acquire --camera folder"
#: Status of a loop that waits for the images of its next round.
AWAITING = "awaiting captures"


def round_folder(index: int) -> str:
    """The folder of round ``index`` (0: the open loop's plan) in an acquisition folder: ``round_00`` …."""
    return f"round_{index:02d}"


def round_pattern(index: int) -> str:
    """The image names of round ``index``: ``r00_000.png`` …, distinct across rounds."""
    return f"r{index:02d}_{{index:03d}}.png"


def round_setup(setup: Setup, index: int) -> Setup:
    """``setup`` whose exports name the images of round ``index`` (:func:`round_pattern`)."""
    problem = setup.problem
    trajectory = dataclasses.replace(problem.trajectory, image_pattern=round_pattern(index))
    return dataclasses.replace(setup, problem=dataclasses.replace(problem, trajectory=trajectory))


class RoundFolders:
    """The folder camera of an acquisition in rounds (module docstring): round i's captures.csv in
    ``folder/round_ii/`` and its images beside it.

    Made before any work, it checks what is there: the rounds whose images are there, in order, each
    with every check of :class:`FolderCamera` (one row per image, distinct lights, no missing file,
    the camera's size); the first round folder without any of its images is the one awaiting
    captures. An acquisition of another problem in ``folder`` is refused."""

    kind = "folder"

    def __init__(self, folder: str | Path, problem: Problem) -> None:
        self.folder = Path(folder)
        _check_same_problem(self.folder, problem)
        camera = Camera.from_spec(problem.camera, problem.object.center_m)
        self.cameras: list[FolderCamera] = []
        while True:
            sub = self.folder / round_folder(len(self.cameras))
            if not (sub / "captures.csv").is_file():
                break
            names, _ = read_captures_csv(sub / "captures.csv")
            if not any((sub / name).is_file() for name in names):
                break  # the round awaiting captures
            self.cameras.append(FolderCamera(sub, camera, problem.light.saturation))

    def camera(self, index: int) -> FolderCamera | None:
        """The camera of round ``index``, None when its images are not there yet."""
        return self.cameras[index] if index < len(self.cameras) else None


def _check_same_problem(folder: Path, problem: Problem) -> None:
    """Refuse to continue an acquisition ``folder`` begun with another problem definition."""
    try:
        document = json.loads((folder / "acquisition.json").read_text())
    except (OSError, ValueError):
        return  # nothing begun there
    before = document.get("problem_definition") if isinstance(document, dict) else None
    if before is not None and before != json.loads(json.dumps(json_safe(problem.to_dict()))):
        raise UsageError(
            "--out",
            f"{folder} holds an acquisition of another problem definition ({document.get('problem')}): "
            "continue it with the problem file as it was, or give a new folder",
        )
