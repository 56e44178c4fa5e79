"""The terms of an objective: functions of the normalised luminance u of the compared pixels to a
scalar (histogram distance, image, mean, contrast, saturation and shadow fractions), and
:func:`make_term`, which builds one from the problem file."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Protocol

import casadi as ca
import numpy as np
from numpy.typing import NDArray

from optlight.errors import ProblemError
from optlight.objectives.histogram import (
    Distance,
    SoftHistogram,
    histogram_distance_casadi,
    histogram_distance_numpy,
)

if TYPE_CHECKING:
    from optlight.objectives.references import Reference
    from optlight.spec import TermSpec

Array = NDArray[np.float64]

#: Default level ℓ (normalised luminance) of the saturation and shadow terms.
DEFAULT_LEVELS = {"saturation": 0.98, "shadow": 0.05}


class Term(Protocol):
    """One objective term: the same scalar from NumPy (batched over leading axes) and CasADi."""

    def numpy(self, u: Array) -> Array:
        """Value(s) for ``u`` of shape (..., P); shape (...)."""
        ...

    def casadi(self, u: ca.MX) -> ca.MX:
        """Value for the P×1 column ``u``, a scalar MX."""
        ...


@dataclass(frozen=True)
class HistogramTerm:
    """Distance between the soft histogram of ``u`` and a reference histogram (K,)."""

    histogram: SoftHistogram
    reference: Array
    distance: Distance = "emd2"

    def numpy(self, u: Array) -> Array:
        return histogram_distance_numpy(self.distance, self.histogram.numpy(u), self.reference)

    def casadi(self, u: ca.MX) -> ca.MX:
        return histogram_distance_casadi(self.distance, self.histogram.casadi(u), self.reference)


@dataclass(frozen=True)
class ImageTerm:
    """Mean squared photometric error (1/P) Σ (u_i − u_i^ref)² against reference pixels (P,)."""

    reference: Array

    def numpy(self, u: Array) -> Array:
        return ((u - self.reference) ** 2).mean(axis=-1)

    def casadi(self, u: ca.MX) -> ca.MX:
        return ca.sumsqr(u - ca.DM(self.reference)) / u.size1()


@dataclass(frozen=True)
class MeanTerm:
    """Target mean luminance: (ū − target)²."""

    target: float

    def numpy(self, u: Array) -> Array:
        return (u.mean(axis=-1) - self.target) ** 2

    def casadi(self, u: ca.MX) -> ca.MX:
        return (ca.sum1(u) / u.size1() - self.target) ** 2


@dataclass(frozen=True)
class ContrastTerm:
    """Target contrast: (σ_u − target)², σ_u the population standard deviation of u."""

    target: float

    def numpy(self, u: Array) -> Array:
        return (u.std(axis=-1) - self.target) ** 2

    def casadi(self, u: ca.MX) -> ca.MX:
        p = u.size1()
        return (ca.sqrt(ca.sumsqr(u - ca.sum1(u) / p) / p) - self.target) ** 2


@dataclass(frozen=True)
class FractionTerm:
    """Soft fraction of saturated (``above=True``: S((u − ℓ)/τ)) or shadowed (S((ℓ − u)/τ)) pixels."""

    level: float
    softness: float
    above: bool

    def numpy(self, u: Array) -> Array:
        x = (u - self.level) / (self.softness if self.above else -self.softness)
        return (0.5 * (1.0 + np.tanh(0.5 * x))).mean(axis=-1)

    def casadi(self, u: ca.MX) -> ca.MX:
        x = (u - self.level) / (self.softness if self.above else -self.softness)
        return ca.sum1(0.5 * (1.0 + ca.tanh(0.5 * x))) / u.size1()


def make_term(spec: TermSpec, reference: Reference, histogram: SoftHistogram, file: str, index: int) -> Term:
    """One :class:`Term` from an ``[[objective.terms]]`` table; errors name the file and the key."""
    where = f"objective.terms[{index}]"
    if spec.kind == "histogram":
        return HistogramTerm(histogram, reference.histogram, spec.distance)
    if spec.kind == "image":
        if reference.pixels is None:
            raise ProblemError(file, f"{where}.kind", "a reference image or light for kind = 'image'", "bins")
        return ImageTerm(reference.pixels)
    if spec.kind in ("mean", "contrast"):
        if spec.target is None:
            raise ProblemError(file, f"{where}.target", f"a target value (kind = '{spec.kind}')")
        return MeanTerm(spec.target) if spec.kind == "mean" else ContrastTerm(spec.target)
    level = spec.level if spec.level is not None else DEFAULT_LEVELS[spec.kind]
    return FractionTerm(level, spec.softness, above=spec.kind == "saturation")
