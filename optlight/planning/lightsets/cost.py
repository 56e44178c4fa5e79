"""Set terms and set costs (docs/design.md §10): the :class:`SetTerm` protocol (a NumPy twin
``numpy(D, p)`` and a CasADi expression ``casadi(D, p)`` of the N×3 directions with parameters ``p``
held fixed during a solve), the image objective averaged over the lights (:class:`ImageSetTerm`)
and the weighted sum of terms (:class:`SetCost`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Protocol

import casadi as ca
import numpy as np

from optlight.errors import OptlightError
from optlight.planning.lightsets.directions import Array

if TYPE_CHECKING:
    from optlight.objectives import Objective
    from optlight.scene import Scene


class SetTerm(Protocol):
    """A scalar of a light set: the same number from NumPy and from CasADi for the same parameters."""

    def parameter_size(self, n: int) -> int:
        """Length of the parameter vector for N lights (0 when the term has none)."""
        ...

    def parameters(self, directions: Array) -> Array:
        """The parameters (held fixed during a solve) at directions (N, 3); shape (parameter_size,)."""
        ...

    def numpy(self, directions: Array, parameters: Array | None = None) -> float:
        """Value at directions (N, 3); ``parameters`` None computes them at ``directions``."""
        ...

    def casadi(self, directions: ca.MX, parameters: ca.MX) -> ca.MX:
        """Value for the N×3 MX ``directions`` and the MX ``parameters``, a scalar MX."""
        ...


class NoParameters:
    """Mixin of the terms that need no parameters."""

    def parameter_size(self, n: int) -> int:
        return 0

    def parameters(self, directions: Array) -> Array:
        return np.zeros(0)


class ImageSetTerm:
    """An image objective applied to each light and averaged: ``(1/N) Σ_i J(a(d_i), v_i)``.

    ``J`` is ``objective.function`` (the smooth differentiable model) at the light position
    ``a(d) = O + b R_WS d``; the parameters are the cast-shadow masks ``v_i`` (P, N) from the scene's
    shadow rays. The NumPy twin scores the NumPy renderer's (exact, non-smooth) images with the same
    masks, so the two differ by the model's smoothing, as :meth:`Objective.function` and the exact
    cost of a landmark do."""

    def __init__(self, objective: Objective, scene: Scene) -> None:
        self.objective = objective
        self.scene = scene
        self.sphere = scene.sphere

    def positions(self, directions: Array) -> Array:
        """Light positions (N, 3), world frame, m."""
        return (
            self.sphere.center + self.sphere.radius * np.asarray(directions, float) @ self.sphere.rotation.T
        )

    def parameter_size(self, n: int) -> int:
        return self.scene.gbuffer.size * n

    def parameters(self, directions: Array) -> Array:
        masks = [self.scene.visibility(a) for a in self.positions(directions)]
        return np.column_stack(masks).ravel(order="F")

    def numpy(self, directions: Array, parameters: Array | None = None) -> float:
        p = self.parameters(directions) if parameters is None else np.asarray(parameters, float)
        masks = p.reshape(self.scene.gbuffer.size, len(directions), order="F")
        costs = [
            self.objective.numpy(self.scene.pixels(a, masks[:, i]))
            for i, a in enumerate(self.positions(directions))
        ]
        return float(np.mean(costs))

    def casadi(self, directions: ca.MX, parameters: ca.MX) -> ca.MX:
        n = directions.size1()
        size = self.scene.gbuffer.size
        positions = ca.DM(self.sphere.center) + self.sphere.radius * ca.mtimes(
            ca.DM(self.sphere.rotation), directions.T
        )
        f = self.objective.function
        total = ca.MX(0)
        for i in range(n):
            total = total + f(positions[:, i], parameters[i * size : (i + 1) * size])
        return total / n


@dataclass(frozen=True)
class SetCost:
    """``Σ_k w_k · term_k`` over set terms; the parameters are the terms' parameters, concatenated."""

    terms: tuple[tuple[float, SetTerm], ...]

    def __init__(self, terms: Sequence[tuple[float, SetTerm]]) -> None:
        if not terms:
            raise OptlightError("a set cost needs at least one term")
        object.__setattr__(self, "terms", tuple((float(w), t) for w, t in terms))

    def parameter_size(self, n: int) -> int:
        return sum(t.parameter_size(n) for _, t in self.terms)

    def parameters(self, directions: Array) -> Array:
        return np.concatenate([np.zeros(0), *(t.parameters(directions) for _, t in self.terms)])

    def numpy(self, directions: Array, parameters: Array | None = None) -> float:
        d = np.asarray(directions, float)
        p = self.parameters(d) if parameters is None else np.asarray(parameters, float)
        total, start = 0.0, 0
        for w, t in self.terms:
            size = t.parameter_size(len(d))
            total += w * t.numpy(d, p[start : start + size])
            start += size
        return total

    def casadi(self, directions: ca.MX, parameters: ca.MX) -> ca.MX:
        total, start = ca.MX(0), 0
        for w, t in self.terms:
            size = t.parameter_size(directions.size1())
            total = total + w * t.casadi(directions, parameters[start : start + size])
            start += size
        return total
