"""The landmark types (docs/design.md §5): a :class:`Landmark`, the sweep's :class:`CostGrid` and
the :class:`LandmarkSet` a search returns. Angles in radians, lengths in metres.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import NDArray

Array = NDArray[np.float64]
Progress = Callable[[int, int], None]


@dataclass(frozen=True)
class Landmark:
    """One landmark: light at ``zenith``, ``azimuth`` (rad) = ``position`` (world, m).

    ``cost``: the objective there (NumPy renderer, shadow rays, the camera's resolution).
    ``status``: "refined" when a refinement's solution won, "polished" when the camera-resolution
    polish did, "sweep" when a sweep sample did; "placed" when the robot could not reach the search's
    landmark and the joint-space placement (:mod:`optlight.planning.placement`) moved it along its
    azimuth to the best light the robot reaches (where that NLP finds none clear of the environment,
    to the clear light nearest it on the azimuth).
    ``solver_status``: the return status of the winning solve (IPOPT's in free mode, "converged" or
    scipy's message for the zenith search of azimuth mode; of the first solve when the sweep won; ""
    when no solve ran). ``iterations``: over all solves of this landmark, IPOPT iterations (free
    mode) or objective evaluations of the zenith search (azimuth mode).
    ``time_s``: wall time of this landmark's own work (azimuth mode: from the previous landmark's
    end, the wait for its sweep included, which ran during the previous one's refinement; free mode:
    its refinement, the shared 2-D sweep excluded)."""

    index: int
    zenith: float
    azimuth: float
    position: Array
    cost: float
    status: Literal["refined", "polished", "sweep", "placed", "set", "grid"]
    solver_status: str
    iterations: int
    time_s: float


@dataclass(frozen=True)
class CostGrid:
    """Objective values of a sweep: ``cost[j, i]`` at ``azimuth[j]``, ``zenith[i]`` (rad), at the
    search resolution."""

    zenith: Array
    azimuth: Array
    cost: Array


@dataclass(frozen=True)
class LandmarkSet:
    """The result of :func:`find_landmarks`.

    ``landmarks`` in azimuth order (azimuth mode) or best first (free mode); ``histograms`` (n, K)
    their soft histograms and ``reference_histogram`` (K,) the reference's, at the camera's
    resolution; ``sweep`` the coarse sweep; ``resolution`` (width, height) of the search renders;
    ``time_s`` the total wall time, setup (scenes, reference, NLP build) included. ``view_zenith``
    (rad): lights nearer the camera's axis were left out, their housing being in the camera's view;
    ``notes``: the landmarks whose best light lay there, and where the best clear light is.
    ``shadows``: each landmark's cast-shadow visibility at the camera's resolution, the one its
    shadow rays gave as it was scored, bits packed along the object pixels (:meth:`visibility`);
    None when they were not kept."""

    landmarks: tuple[Landmark, ...]
    mode: Literal["azimuth", "free", "set"]
    reference_histogram: Array
    reference_label: str
    histograms: Array
    sweep: CostGrid
    resolution: tuple[int, int]
    time_s: float
    view_zenith: float = 0.0
    notes: tuple[str, ...] = ()
    shadows: NDArray[np.uint8] | None = None

    def __len__(self) -> int:
        return len(self.landmarks)

    def visibility(self, pixels: int) -> Array | None:
        """The landmarks' cast-shadow visibility (n, ``pixels``) in {0., 1.} over the camera's
        ``pixels`` object pixels (:meth:`optlight.scene.Scene.visibility` at each landmark's light);
        None when :attr:`shadows` were not kept."""
        if self.shadows is None:
            return None
        return np.unpackbits(self.shadows, axis=1, count=pixels).astype(float)

    @property
    def zeniths(self) -> Array:
        """Zeniths (n,), rad."""
        return np.array([lm.zenith for lm in self.landmarks])

    @property
    def azimuths(self) -> Array:
        """Azimuths (n,), rad."""
        return np.array([lm.azimuth for lm in self.landmarks])

    @property
    def positions(self) -> Array:
        """Light positions (n, 3), world frame, m."""
        return np.array([lm.position for lm in self.landmarks]).reshape(-1, 3)

    @property
    def costs(self) -> Array:
        """Objective values (n,) at the camera's resolution."""
        return np.array([lm.cost for lm in self.landmarks])

    @property
    def iterations(self) -> int:
        """Solver iterations (see :class:`Landmark`) over all landmarks."""
        return sum(lm.iterations for lm in self.landmarks)
