"""The composed objective: a weighted sum of terms of the compared pixels' normalised luminance, and
its CasADi Function through the scene's differentiable luminance model."""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

import casadi as ca
import numpy as np
from numpy.typing import ArrayLike, NDArray

from optlight.errors import OptlightError, ProblemError
from optlight.objectives.histogram import SoftHistogram, histogram_distance_numpy
from optlight.objectives.references import (
    Reference,
    reference_from_bins,
    reference_from_image,
    reference_from_light,
)
from optlight.objectives.terms import HistogramTerm, Term, make_term

if TYPE_CHECKING:
    from optlight.scene import Scene
    from optlight.spec import Problem

Array = NDArray[np.float64]

class Objective:
    """A weighted sum of terms of the normalised luminance of the compared pixels.

    ``cost(I) = Σ_t w_t · term_t(I[selection] / saturation)`` for the object's pixel vector ``I``
    (P,), in the renderer's units. :meth:`numpy` and :meth:`casadi` compute the same number;
    :attr:`function` is the CasADi Function ``(a: 3×1 light position, v: P×1 visibility) -> cost``
    through the scene's differentiable luminance model, built once, on first use."""

    def __init__(
        self,
        terms: Sequence[tuple[float, Term]],
        reference: Reference,
        histogram: SoftHistogram,
        *,
        saturation: float = 1.0,
        luminance: ca.Function | None = None,
    ) -> None:
        if not terms:
            raise OptlightError("an objective needs at least one term")
        self.terms = tuple(terms)
        self.reference = reference
        self.histogram = histogram
        self.saturation = float(saturation)
        self.selection = reference.selection
        self._luminance = luminance
        self._function: ca.Function | None = None

    @classmethod
    def from_problem(cls, problem: Problem, scene: Scene) -> Objective:
        """The objective of a problem file (``[objective]``), its reference built with ``scene``."""
        spec = problem.objective
        file = str(problem.source) if problem.source else "<inline>"
        histogram = SoftHistogram(spec.bins, spec.sigma_bins)
        saturation = problem.light.saturation
        ref = spec.reference
        reference: Reference
        if ref.kind == "light":
            reference = reference_from_light(
                scene, histogram, np.deg2rad(ref.zenith_deg), np.deg2rad(ref.azimuth_deg), saturation
            )
        elif ref.kind == "image":
            if ref.image is None:
                raise ProblemError(
                    file, "objective.reference.image", "an image path (reference.kind = 'image')"
                )
            mask = None if ref.mask is None else problem.resolve(ref.mask)
            size = None if ref.resize else (problem.camera.width, problem.camera.height)
            reference = reference_from_image(
                scene, histogram, problem.resolve(ref.image), mask, saturation, file, size
            )
        else:
            if ref.bins is None:
                raise ProblemError(
                    file, "objective.reference.bins", "the reference bins (reference.kind = 'bins')"
                )
            reference = reference_from_bins(ref.bins)
        terms = [(t.weight, make_term(t, reference, histogram, file, i)) for i, t in enumerate(spec.terms)]
        return cls(terms, reference, histogram, saturation=saturation, luminance=scene.luminance(smooth=True))

    def normalise(self, pixels: ArrayLike) -> Array:
        """The compared pixels in normalised luminance: ``I[..., selection] / saturation``."""
        u = np.asarray(pixels, float) / self.saturation
        return u if self.selection is None else u[..., self.selection]

    def numpy_batch(self, pixels: ArrayLike) -> Array:
        """Costs of a batch of pixel vectors (S, P) -> (S,)."""
        u = self.normalise(pixels)
        return sum((w * t.numpy(u) for w, t in self.terms), np.zeros(u.shape[:-1]))

    def numpy(self, pixels: ArrayLike) -> float:
        """Cost of one pixel vector (P,), renderer units."""
        return float(self.numpy_batch(np.asarray(pixels, float)[None])[0])

    def casadi(self, pixels: ca.MX) -> ca.MX:
        """Cost of a P×1 MX pixel vector (renderer units), a scalar MX; the CasADi twin of :meth:`numpy`."""
        u = pixels / self.saturation
        if self.selection is not None:
            u = u[[int(i) for i in self.selection]]
        cost = ca.MX(0)
        for w, t in self.terms:
            cost = cost + w * t.casadi(u)
        return cost

    def __call__(self, pixels: ca.MX) -> ca.MX:
        """``objective(I)``: the same as :meth:`casadi`, for composing into other NLPs."""
        return self.casadi(pixels)

    def evaluate(self, pixels: ArrayLike) -> tuple[float, Array]:
        """Cost of one pixel vector (P,), as :meth:`numpy`, and the soft histogram (K,) of its
        compared pixels, computed once for both: the histogram terms on the objective's own histogram
        take their distance from it (the histogram is most of the time a cost takes)."""
        u = self.normalise(np.asarray(pixels, float))
        histogram = self.histogram.numpy(u)
        cost = 0.0
        for w, t in self.terms:
            if isinstance(t, HistogramTerm) and t.histogram == self.histogram:
                cost += w * float(histogram_distance_numpy(t.distance, histogram, t.reference))
            else:
                cost += w * float(t.numpy(u))
        return cost, histogram

    @property
    def function(self) -> ca.Function:
        """CasADi Function (a: 3×1 light position, v: P×1 visibility) -> scalar cost, built once."""
        if self._luminance is None:
            raise OptlightError("this objective was built without a luminance model (pass luminance=...)")
        if self._function is None:  # on first use: the camera-resolution objective rarely needs one
            self._function = self._compose(self._luminance)
        return self._function

    def _compose(self, luminance: ca.Function) -> ca.Function:
        a = ca.MX.sym("a", 3)
        v = ca.MX.sym("v", luminance.size1_in(1))
        return ca.Function("objective", [a, v], [self.casadi(luminance(a, v))], ["a", "v"], ["cost"])
