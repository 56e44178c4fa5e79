"""Shared fixtures: built-in problems reduced to test sizes, and built setups of them; the display
mesh cache in a temporary folder for the session, so that tests never write to the user's cache.

Tests import :func:`reduced_problem` (``from conftest import reduced_problem``) where a module needs
its own variant at import time; fixtures give the common ones, built once per session.
"""

from __future__ import annotations

import hashlib
import os
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from optlight.planning.landmarks import LandmarkSet, find_landmarks
from optlight.planning.policy import Reacher
from optlight.setup import Setup
from optlight.spec import Problem, load_problem, problem_from_dict


@pytest.fixture(scope="session", autouse=True)
def private_mesh_cache(tmp_path_factory: pytest.TempPathFactory) -> Iterator[None]:
    """``OPTLIGHT_CACHE`` set to a folder of this session (processes the tests start inherit it)."""
    before = os.environ.get("OPTLIGHT_CACHE")
    os.environ["OPTLIGHT_CACHE"] = str(tmp_path_factory.mktemp("optlight-cache"))
    yield
    if before is None:
        del os.environ["OPTLIGHT_CACHE"]
    else:
        os.environ["OPTLIGHT_CACHE"] = before


#: The paper's layout (the robot's base between the camera and the face) with the camera's view not
#: protected, for tests about reach alone: there the reference light (zenith 10°) and the pole are
#: lights the search may propose. The view at the planning stage is tested in test_view_plan.py.
REACH_ONLY: dict[str, dict[str, Any]] = {
    "object": {"center_m": [0.35, 0.0, 0.45]},
    "camera": {"position_m": [-0.343, -0.4, 0.45]},
    "view": {"mode": "off"},
}


def reduced_problem(name: str = "default", *, camera_px: int | None = None, **sections: dict[str, Any]) -> Problem:
    """A built-in problem with a ``camera_px``² camera (when given) and each of ``sections``
    (``landmarks={"count": 8}``, ``object={"face": {"resolution": 48}}`` …) merged key by key into the
    file's section; the source path is kept so that relative data paths still resolve."""
    original = load_problem(name)
    data = original.to_dict()
    if camera_px is not None:
        data["camera"].update(width=camera_px, height=camera_px)
    for section, values in sections.items():
        data.setdefault(section, {}).update(values)
    return problem_from_dict(data, source=original.source)


@pytest.fixture(scope="session")
def small_default() -> Problem:
    """The default problem with a 96² camera and 8 landmarks: the whole pipeline in seconds."""
    return reduced_problem(camera_px=96, landmarks={"count": 8})


@pytest.fixture(scope="session")
def small_setup(small_default: Problem) -> Setup:
    """:func:`small_default` built once."""
    return Setup.from_problem(small_default)


def reacher_of(setup: Setup) -> Reacher:
    """The reacher a solve builds for ``setup``: its work cell, ``[solver]`` and image costs."""
    return Reacher(setup.workcell, setup.solver, setup.image_costs)


def search_landmarks(setup: Setup, **kwargs: Any) -> LandmarkSet:
    """The landmark search of a solve over ``setup`` (``find_landmarks`` with what it takes of it)."""
    return find_landmarks(
        setup.workcell, setup.image_costs, setup.landmark_spec, setup.solver, setup.file, **kwargs
    )


def snapshot(root: Path) -> dict[str, str]:
    """Every entry below ``root`` (hidden ones too): a file's SHA-256, a link's target, "dir"; what
    the tests compare to show that a run changed nothing of the user's."""
    out = {}
    for path in sorted(root.rglob("*")):
        rel = str(path.relative_to(root))
        if path.is_symlink():
            out[rel] = "link:" + os.readlink(path)
        elif path.is_dir():
            out[rel] = "dir"
        else:
            out[rel] = hashlib.sha256(path.read_bytes()).hexdigest()
    return out
