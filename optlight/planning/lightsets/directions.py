"""Light directions on the allowed cap (docs/design.md §10): the :class:`Cap`, the angles of a
direction, rings, and the coverage measures of a set (max-min separation, covering radius).

A light set is N unit directions ``d_i`` from the object centre O towards the lights, in the light
sphere's frame S (docs/design.md §2: ``z_S`` towards the camera, so zenith 0 is frontal light), with
``d_i = (sinθ_i cosφ_i, sinθ_i sinφ_i, cosθ_i)`` and ``θ_min ≤ θ_i ≤ θ_max`` on the cap.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import casadi as ca
import numpy as np
from numpy.typing import ArrayLike, NDArray

from optlight.errors import OptlightError
from optlight.geometry import LightSphere, direction_in_sphere_frame

Array = NDArray[np.float64]


@dataclass(frozen=True)
class Cap:
    """The allowed zenith range [``zenith_min``, ``zenith_max``] (rad) on the light sphere."""

    zenith_min: float
    zenith_max: float

    def __post_init__(self) -> None:
        if not 0.0 <= self.zenith_min < self.zenith_max <= math.pi:
            raise OptlightError(
                f"a cap needs 0 ≤ zenith_min < zenith_max ≤ π, got {self.zenith_min}, {self.zenith_max}"
            )

    @classmethod
    def from_sphere(cls, sphere: LightSphere) -> Cap:
        """The cap of a light sphere (its ``zenith_min``, ``zenith_max``)."""
        return cls(float(sphere.zenith_min), float(sphere.zenith_max))

    def contains(self, directions: ArrayLike, tol: float = 1e-9) -> NDArray[np.bool_]:
        """Whether each unit direction (..., 3), sphere frame, lies on the cap (zenith within ``tol``)."""
        zenith, _ = angles_of(directions)
        return (zenith >= self.zenith_min - tol) & (zenith <= self.zenith_max + tol)

    def lattice(self, count: int) -> Array:
        """``count`` directions (count, 3) spread evenly over the cap's area: a Fibonacci lattice,
        cos θ uniform on [cos θ_max, cos θ_min] and azimuths stepping by the golden angle."""
        k = np.arange(count) + 0.5
        z = math.cos(self.zenith_min) - k / count * (math.cos(self.zenith_min) - math.cos(self.zenith_max))
        azimuth = np.mod(k * math.pi * (3.0 - math.sqrt(5.0)), 2 * math.pi)
        return direction_in_sphere_frame(np.arccos(z), azimuth)

    def random(self, count: int, rng: np.random.Generator) -> Array:
        """``count`` directions (count, 3) drawn uniformly on the cap's area."""
        z = rng.uniform(math.cos(self.zenith_max), math.cos(self.zenith_min), count)
        return direction_in_sphere_frame(np.arccos(z), rng.uniform(0.0, 2 * math.pi, count))

    def area_count(self, spacing: float) -> int:
        """How many lattice points give neighbours about ``spacing`` (rad) apart: area / spacing²."""
        area = 2 * math.pi * (math.cos(self.zenith_min) - math.cos(self.zenith_max))
        return max(1, math.ceil(area / spacing**2))


def angles_of(directions: ArrayLike) -> tuple[Array, Array]:
    """Zenith θ ∈ [0, π] and azimuth φ ∈ [0, 2π) of directions (..., 3) in the sphere frame."""
    d = np.asarray(directions, float)
    zenith = np.arctan2(np.hypot(d[..., 0], d[..., 1]), d[..., 2])
    return zenith, np.mod(np.arctan2(d[..., 1], d[..., 0]), 2 * math.pi)


def casadi_directions(x: ca.MX) -> ca.MX:
    """The N×3 MX of directions from ``x = (θ_1 … θ_N, φ_1 … φ_N)`` (2N×1)."""
    n = x.size1() // 2
    zenith, azimuth = x[:n], x[n:]
    return ca.horzcat(ca.sin(zenith) * ca.cos(azimuth), ca.sin(zenith) * ca.sin(azimuth), ca.cos(zenith))


def ring_directions(n: int, slant: float, phase: float = 0.0) -> Array:
    """N lights (n, 3) at zenith ``slant`` (rad), azimuths ``phase + 2πi/n``."""
    return direction_in_sphere_frame(np.full(n, slant), phase + 2 * math.pi * np.arange(n) / n)


def min_separation(directions: ArrayLike) -> float:
    """The smallest angle (rad) between two of the directions (N, 3), N ≥ 2."""
    d = np.asarray(directions, float)
    gram = d @ d.T
    np.fill_diagonal(gram, -1.0)
    return float(np.arccos(np.clip(gram.max(), -1.0, 1.0)))


def covering_radius(directions: ArrayLike, cap: Cap, samples: int = 20_000) -> float:
    """The largest angle (rad) from a point of the cap (a lattice of ``samples`` points) to its
    nearest light: every point of the cap is within this angle of a light."""
    gram = cap.lattice(samples) @ np.asarray(directions, float).T
    return float(np.arccos(np.clip(gram.max(axis=1).min(), -1.0, 1.0)))


def coverage(directions: ArrayLike, cap: Cap) -> dict[str, float]:
    """RTI coverage report (degrees): ``min_separation_deg`` (max-min separation of the set) and
    ``covering_radius_deg`` (:func:`covering_radius`)."""
    return {
        "min_separation_deg": math.degrees(min_separation(directions)),
        "covering_radius_deg": math.degrees(covering_radius(directions, cap)),
    }
