"""The soft histogram of the normalised luminance and the distances between histograms (the package
docstring states both), each with a NumPy and a CasADi twin."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import casadi as ca
import numpy as np
from numpy.typing import ArrayLike, NDArray

from optlight.errors import OptlightError

Array = NDArray[np.float64]
Distance = Literal["l2", "chi2", "emd", "emd2"]

#: ε of the χ² denominator.
CHI2_EPS = 1e-10
#: δ of the smooth absolute value in the ``emd`` distance.
EMD_SMOOTH_ABS = 1e-4
#: Kernel values below e^−_LOG_DROP of the peak are left out of :meth:`SoftHistogram.numpy`: e^−40 ≈
#: 4e-18, below float64's resolution of the pixel's own kernel mass, sets how many bins a pixel reaches.
_LOG_DROP = 40.0
#: Pixels farther than √_LOG_SPAN kernel widths from the nearest bin centre are left out (their kernel
#: values are below e^−600).
_LOG_SPAN = 600.0
#: Kernel sums one piece of :meth:`SoftHistogram.numpy` works on (rows × pixels): its arrays stay in
#: cache (2^15 measured fastest on a 256² image and on a batch of 32 64² images).
_PIECE = 2**15
#: Longest reach (S − 1)δ of a chain of products in :meth:`SoftHistogram.casadi`, and the bound
#: on |x| there, in units of ``a``: products, and the adjoints of the reverse derivative, stay below
#: e^(2 · 27 · 12) = e^648 (float64 ends at e^709); what the bound leaves out is below e^−(27 − 12)².
_CHAIN_REACH = 12.0
_CHAIN_BOUND = 27.0


@dataclass(frozen=True)
class SoftHistogram:
    """Gaussian soft histogram of normalised luminance: ``bins`` bins on [0, 1], kernel width
    ``σ = sigma_bins / bins`` (see the module docstring for the formula)."""

    bins: int = 32
    sigma_bins: float = 1.0

    def __post_init__(self) -> None:
        if self.bins < 2 or not self.sigma_bins > 0:
            raise OptlightError(
                f"SoftHistogram needs bins ≥ 2 and sigma_bins > 0, got {self.bins}, {self.sigma_bins}"
            )

    @property
    def width(self) -> float:
        """Bin width w = 1/K."""
        return 1.0 / self.bins

    @property
    def centres(self) -> Array:
        """Bin centres c_k = (k + ½) w, shape (K,)."""
        return (np.arange(self.bins, dtype=float) + 0.5) / self.bins

    @property
    def sigma(self) -> float:
        """Kernel standard deviation σ = sigma_bins · w."""
        return self.sigma_bins * self.width

    def numpy(self, u: ArrayLike) -> Array:
        """Histogram(s) of ``u`` with shape (..., P) -> (..., K), each summing to 1.

        The kernel sums ``h̃_k = Σ_i exp(−(a_i − b_k)²)``, ``a = u/(σ√2)``, ``b_k = (k + ½)δ``,
        ``δ = w/(σ√2)``, without a P×K table of exponentials (float64 ``exp`` is scalar code on
        AVX2 machines, ~9 ns a value): with ``r_i`` the bin nearest ``a_i``, ``t_i = a_i − b_{r_i}``
        and ``k = r_i + m``,

            exp(−(a_i − b_k)²) = s_i e_i^(m+W) · exp(−m²δ²),
            s_i = exp(−t_i² − 2Wδ t_i),   e_i = exp(2δ t_i),

        two exponentials per pixel, one product per pixel and offset ``m ∈ [−W, W]``, and the pixels
        summed by their ``r_i`` (``np.bincount``) before the factor ``exp(−m²δ²)``, which depends on
        ``m`` only. Offsets beyond ``W`` are left out: there ``|a_i − b_k| ≥ (W + ½)δ``, so
        ``W = ⌈√(_LOG_DROP)/δ − ½⌉`` (at most K − 1) leaves out kernel values below e^−40 of the
        peak (9 bins at ``sigma_bins`` = 1: 19 sums per pixel where every bin would take 32). The
        running product stays below ``exp(W²δ²)``; ``e_i`` below ``exp(δ²)`` inside the bins' range
        and ``exp(2δ√(_LOG_SPAN))`` beyond it, finite while W > 0 (``δ < 2√(_LOG_DROP)``; W = 0 takes
        no ``e_i``). Within 1e-11 of the direct sums relative (tested).
        Pieces of :data:`_PIECE` values, rows of a batch or pixel slices of one image, are summed in a
        fixed order.
        """
        u = np.asarray(u, float)
        batch = u.reshape(-1, u.shape[-1])
        n_rows, n_pixels = batch.shape
        a = batch * (math.sqrt(0.5) / self.sigma)
        rows = max(1, _PIECE // n_pixels)
        cols = n_pixels if rows > 1 else _PIECE
        out = np.zeros((n_rows, self.bins))
        for i in range(0, n_rows, rows):
            for j in range(0, n_pixels, cols):
                out[i : i + rows] += self._kernel_sums(a[i : i + rows, j : j + cols])
        out /= out.sum(axis=1, keepdims=True)
        return out.reshape(*u.shape[:-1], self.bins)

    def _kernel_sums(self, a: Array) -> Array:
        """``Σ_i exp(−(a_i − b_k)²)`` per row of ``a`` (n, p) -> (n, K), offsets ``−W … W`` from
        each pixel's nearest bin (the factorisation of :meth:`numpy`)."""
        n, bins = a.shape[0], self.bins
        delta = math.sqrt(0.5) / self.sigma_bins
        half = min(bins - 1, max(0, math.ceil(math.sqrt(_LOG_DROP) / delta - 0.5)))
        r = np.clip(np.floor(a / delta).astype(np.intp), 0, bins - 1)
        t = a - (r + 0.5) * delta
        near = t * t <= _LOG_SPAN
        t = np.where(near, t, 0.0)
        v = np.where(near, np.exp(-t * t - 2 * half * delta * t), 0.0).ravel()
        e = np.exp(2 * delta * t).ravel() if half else v  # W = 0: no products, and exp(2δt) may overflow
        keys = (r + bins * np.arange(n)[:, None]).ravel()
        # column j of the padded sums is bin j − W: the pixels of bin r add to column r + m + W
        padded = np.zeros((n, bins + 2 * half))
        for j in range(2 * half + 1):
            if j:
                v *= e
            sums = np.bincount(keys, weights=v, minlength=n * bins).reshape(n, bins)
            padded[:, j : j + bins] += sums * math.exp(-(((j - half) * delta) ** 2))
        return padded[:, half : half + bins]

    def casadi(self, u: ca.MX) -> ca.MX:
        """Histogram of the column ``u`` (P×1) as a K×1 MX: the kernel sums of :meth:`numpy`, bin
        after bin along a chain of products instead of one exponential per pixel and bin (float64
        ``exp`` was most of the objective's time: 0.52 of 0.59 ms on the default face's 1,840
        search pixels).

        With ``a``, ``b_k``, ``δ`` as in :meth:`numpy`, the bins are cut into equal segments of at
        most ``S`` bins, ``(S − 1)δ ≤ R_max`` (:data:`_CHAIN_REACH`); in the segment from bin ``j``,
        with ``x_i = a_i − b_j`` bounded to ``[−X, X]`` (:data:`_CHAIN_BOUND`),

            exp(−(a_i − b_{j+m})²) = exp(−m²δ²) · v_i,m,    v_i,m = exp(−x_i²) · R_iᵐ,   R_i = exp(2δ x_i),

        so a segment takes two exponentials per pixel, one product per pixel and bin (v_i,m =
        v_i,m−1 R_i) and the constant ``exp(−m²δ²)`` once the pixels are summed. ``v_i,m ≤
        exp(R_max²)``, and the reverse derivative's adjoints, which carry ``R_iᵐ``, stay below
        ``exp(2 X R_max)``; a pixel farther than X from a segment's first bin adds less than
        ``exp(−(X − R_max)²)`` to its bins (e^−225), and nothing to the gradient. Where segments
        would be shorter than 3 bins (``δ`` > 6, ``sigma_bins`` < 0.12) every bin takes its own
        exponential, ``exp(−(a_i − b_k)²)``. Within 1e-12 of the kernel matrix, relative, and so is
        the gradient (tested)."""
        delta = math.sqrt(0.5) / self.sigma_bins
        a = u * (math.sqrt(0.5) / self.sigma)
        longest = 1 + math.floor(_CHAIN_REACH / delta)
        if longest < 3:
            longest = 1
        span = math.ceil(self.bins / math.ceil(self.bins / longest))  # equal segments: short chains
        sums = []
        for j in range(0, self.bins, span):
            x = a - (j + 0.5) * delta
            if span == 1:
                sums.append(ca.sum1(ca.exp(-x * x)))
                continue
            x = ca.fmax(ca.fmin(x, _CHAIN_BOUND), -_CHAIN_BOUND)
            v, r = ca.exp(-x * x), ca.exp(2 * delta * x)
            sums.append(ca.sum1(v))
            for m in range(1, min(span, self.bins - j)):
                v = v * r
                sums.append(ca.sum1(v) * math.exp(-((m * delta) ** 2)))
        h = ca.vertcat(*sums)
        return h / ca.sum1(h)


def _smooth_abs_np(x: Array) -> Array:
    return np.sqrt(x * x + EMD_SMOOTH_ABS**2) - EMD_SMOOTH_ABS


def histogram_distance_numpy(distance: Distance, h: ArrayLike, r: ArrayLike) -> Array:
    """Distance between histograms ``h`` (..., K) and ``r`` (K,); shape (...). Formulas: module doc."""
    h, r = np.asarray(h, float), np.asarray(r, float)
    k = h.shape[-1]
    if distance == "l2":
        return ((h - r) ** 2).sum(axis=-1)
    if distance == "chi2":
        return ((h - r) ** 2 / (h + r + CHI2_EPS)).sum(axis=-1)
    cdf = np.cumsum(h - r, axis=-1)
    if distance == "emd":
        return _smooth_abs_np(cdf).sum(axis=-1) / k
    if distance == "emd2":
        return (cdf * cdf).sum(axis=-1) / k
    raise OptlightError(f"unknown histogram distance {distance!r} (l2, chi2, emd, emd2)")


def histogram_distance_casadi(distance: Distance, h: ca.MX, r: ArrayLike) -> ca.MX:
    """CasADi twin of :func:`histogram_distance_numpy` for a K×1 ``h`` and a constant ``r``."""
    r = ca.DM(np.asarray(r, float))
    k = h.size1()
    if distance == "l2":
        return ca.sumsqr(h - r)
    if distance == "chi2":
        return ca.sum1((h - r) ** 2 / (h + r + CHI2_EPS))
    cdf = ca.cumsum(h - r)
    if distance == "emd":
        return ca.sum1(ca.sqrt(cdf * cdf + EMD_SMOOTH_ABS**2) - EMD_SMOOTH_ABS) / k
    if distance == "emd2":
        return ca.sumsqr(cdf) / k
    raise OptlightError(f"unknown histogram distance {distance!r} (l2, chi2, emd, emd2)")
