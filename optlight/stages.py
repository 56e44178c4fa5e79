"""The typed value each stage of a solve hands on, and the hook that hears each stage finish.

:func:`optlight.solve` runs the stages of :data:`optlight.pipeline.STAGES` in order (docs/design.md
§6) and, as each finishes, calls its listener ``on_stage(stage, result)`` (a :data:`StageListener`)
with the stage's result:

========== ===========================================================================
stage      result
========== ===========================================================================
scene      :class:`~optlight.setup.Setup` (also when the caller passed it built)
landmarks  :class:`~optlight.planning.landmarks.LandmarkSet`, the landmark search
placement  :class:`~optlight.planning.policy.LandmarkPlacement`, the captures' joint angles
path       :class:`Route`: the visiting order, the knots and the per-knot IK
nlp        :class:`OptimizedPath`: the captures and the knots the trajectory NLP chose
timing     :class:`~optlight.motion.Trajectory`, the timed motion
verify     :class:`~optlight.verify.VerificationReport`, the independent check
========== ===========================================================================

The solve knows nothing of who listens: the command line subscribes the figure worker
(:class:`optlight.report.FigureDrafts`), which draws each figure as soon as its numbers exist.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from optlight.planning.landmarks import Landmark
from optlight.planning.path import LightPath
from optlight.planning.trajectory import TrajectoryNLPResult

Array = NDArray[np.float64]

#: on_stage(stage, result): called as each stage of :data:`optlight.pipeline.STAGES` finishes, with
#: its result (the module docstring's table).
StageListener = Callable[[str, object], None]


@dataclass(frozen=True)
class Route:
    """What the ``path`` stage hands on: the visiting ``order`` (M,) (indices into the placement's
    landmarks), the captures ``visited`` in that order, their joint angles ``landmark_thetas``
    (M, n, rad), the light's great-circle knots ``path``, the per-knot IK ``knot_ik`` (K, n, rad; the
    NLP's warm start) and, per segment, the knots it missed ``failures`` (M − 1,)."""

    order: NDArray[np.int64]
    visited: tuple[Landmark, ...]
    landmark_thetas: Array
    path: LightPath
    knot_ik: Array
    failures: NDArray[np.int64]


@dataclass(frozen=True)
class OptimizedPath:
    """What the ``nlp`` stage hands on: the captures ``visited`` in visiting order and their joint
    angles ``landmark_thetas`` (M, n, rad) the motion goes through, the ``path`` with the transfers
    its windows needed (the segments the light leaves the sphere on), the per-knot IK ``knot_ik``
    (K, n, rad) it was warm-started at, and the trajectory NLP's result ``nlp`` (its knots
    ``nlp.theta``)."""

    visited: tuple[Landmark, ...]
    landmark_thetas: Array
    path: LightPath
    knot_ik: Array
    nlp: TrajectoryNLPResult
