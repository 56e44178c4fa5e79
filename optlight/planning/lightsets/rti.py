"""The RTI set term (docs/design.md §10): :class:`RieszEnergy`, the mean Riesz s-energy over pairs
of lights, whose minimisers for ``s > 2`` cover the cap evenly.
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

from optlight.planning.lightsets.cost import NoParameters
from optlight.planning.lightsets.directions import Array

#: Default Riesz exponent s (hypersingular on the 2-sphere: s > 2).
DEFAULT_RIESZ_EXPONENT = 4.0


@dataclass(frozen=True)
class RieszEnergy(NoParameters):
    """Riesz s-energy per pair: ``(1/(N(N−1))) Σ_{i≠j} |d_i − d_j|^{−s}`` with
    ``|d_i − d_j|² = 2 − 2 d_i·d_j`` for unit directions; N ≥ 2. Two coincident lights: +inf (the
    NumPy twin, or ~1e30 by rounding; a replacement scores a candidate on another light that way)."""

    exponent: float = DEFAULT_RIESZ_EXPONENT

    def numpy(self, directions: Array, parameters: Array | None = None) -> float:
        d = np.asarray(directions, float)
        n = len(d)
        sq = np.maximum(2.0 - 2.0 * (d @ d.T), 0.0) + np.eye(n)  # 1 on the diagonal: each adds 1, removed below
        with np.errstate(divide="ignore"):
            return float(((sq ** (-0.5 * self.exponent)).sum() - n) / (n * (n - 1)))

    def casadi(self, directions: ca.MX, parameters: ca.MX) -> ca.MX:
        n = directions.size1()
        sq = 2.0 - 2.0 * ca.mtimes(directions, directions.T) + ca.DM.eye(n)
        return (ca.sum1(ca.sum2(sq ** (-0.5 * self.exponent))) - n) / (n * (n - 1))
