"""Luminance objectives (docs/design.md §4): soft histograms, histogram distances, image terms.

Every term is a pure function of the pixel vector of the object, with two twins that compute the
same number: ``numpy(u)`` on arrays (batched over leading axes) and ``casadi(u)`` on an MX column,
built from matrix-valued MX operations and constant matrices — no per-pixel graphs.

Units. Terms see *normalised luminance* ``u = I / s``, the pixel value ``I`` (as rendered by the
scene) divided by the sensor's saturation level ``s`` (``light.saturation``), so ``u ∈ [0, 1]``.
Histogram bins, targets and levels are all in these units.

Soft histogram. ``K`` bins on [0, 1] with centres ``c_k = (k + ½) w``, width ``w = 1/K`` and a
Gaussian kernel of width ``σ = sigma_bins · w``::

    h̃_k = (1/P) Σ_i exp(−(u_i − c_k)² / (2σ²)),      h_k = h̃_k / Σ_j h̃_j.

Distances between histograms ``h`` and ``r`` (both summing to 1), with CDFs ``F_k = Σ_{j≤k} h_j``
and ``G_k = Σ_{j≤k} r_j``:

- ``l2``:   ``Σ_k (h_k − r_k)²`` (the squared Euclidean distance: smooth, 0 at ``h = r``);
- ``chi2``: ``Σ_k (h_k − r_k)² / (h_k + r_k + ε)``, ``ε = 1e-10``;
- ``emd``:  ``w Σ_k |F_k − G_k|_δ``, the 1-D earth mover's (Wasserstein-1) distance ``∫|F − G| du``
  with the smooth absolute value ``|x|_δ = √(x² + δ²) − δ``, ``δ = 1e-4`` (``|x| − δ ≤ |x|_δ ≤ |x|``;
  both twins use it, so they agree exactly and the CasADi gradient exists at ``F = G``);
- ``emd2``: ``w Σ_k (F_k − G_k)²``, its smooth squared form ``∫(F − G)² du``.

Other terms, each a mean over the compared pixels (``P`` of them):

- ``image``:      ``(1/P) Σ_i (u_i − u_i^ref)²``, the mean squared photometric error;
- ``mean``:       ``(ū − t)²`` with ``ū = (1/P) Σ_i u_i``;
- ``contrast``:   ``(σ_u − t)²`` with ``σ_u = √((1/P) Σ_i (u_i − ū)²)``;
- ``saturation``: ``(1/P) Σ_i S((u_i − ℓ)/τ)``, the soft fraction of pixels above level ``ℓ``;
- ``shadow``:     ``(1/P) Σ_i S((ℓ − u_i)/τ)``, the soft fraction of pixels below level ``ℓ``;

with ``S(x) = 1/(1 + e^{−x}) = ½(1 + tanh(x/2))`` the logistic sigmoid (evaluated in the tanh form,
which does not overflow) and ``τ`` its width (``softness``).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Literal, Protocol

import casadi as ca
import numpy as np
from numpy.typing import ArrayLike, NDArray

from optlight.errors import OptlightError, ProblemError

if TYPE_CHECKING:
    from optlight.scene import Scene
    from optlight.spec import Problem, TermSpec

Array = NDArray[np.float64]
Index = NDArray[np.intp]
Distance = Literal["l2", "chi2", "emd", "emd2"]

#: ε of the χ² denominator.
CHI2_EPS = 1e-10
#: δ of the smooth absolute value in the ``emd`` distance.
EMD_SMOOTH_ABS = 1e-4
#: Default level ℓ (normalised luminance) of the saturation and shadow terms.
DEFAULT_LEVELS = {"saturation": 0.98, "shadow": 0.05}
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


# --------------------------------------------------------------------------------------------
# Soft histogram and distances
# --------------------------------------------------------------------------------------------


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


# --------------------------------------------------------------------------------------------
# Terms: u (normalised luminance of the compared pixels) -> scalar
# --------------------------------------------------------------------------------------------


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


# --------------------------------------------------------------------------------------------
# References
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Reference:
    """What the image is compared with, sampled at the object's pixels.

    ``histogram`` (K,) sums to 1; ``pixels`` (P_sel,) are the reference's normalised luminance at the
    compared pixels (None for given bins); ``selection`` indexes the compared pixels among the
    object's P pixels (None = all of them); ``label`` says where the reference came from."""

    histogram: Array
    pixels: Array | None
    selection: Index | None
    label: str


def reference_from_pixels(
    histogram: SoftHistogram, pixels: ArrayLike, selection: ArrayLike | None, label: str
) -> Reference:
    """A reference from normalised luminance at the object's pixels (P,), restricted to ``selection``."""
    u = np.asarray(pixels, float)
    sel = None if selection is None else np.asarray(selection, np.intp)
    u = u if sel is None else u[sel]
    return Reference(histogram.numpy(u), u, sel, label)


def reference_from_bins(bins: ArrayLike, label: str = "given bins") -> Reference:
    """A reference from given histogram bins, renormalised to sum 1."""
    b = np.asarray(bins, float)
    if b.ndim != 1 or (b < 0).any() or b.sum() <= 0:
        raise OptlightError(f"reference bins must be non-negative with a positive sum, got {b}")
    return Reference(b / b.sum(), None, None, label)


def read_image(path: Path, saturation: float, file: str = "<api>", key: str = "") -> Array:
    """A greyscale image as normalised luminance (H, W).

    PNG (or anything Pillow reads): integer values over their full scale (8-bit /255, 16-bit
    /65535), 32-bit float as is, colour converted to luma 0.2126 R + 0.7152 G + 0.0722 B. NPY: pixel values in the
    renderer's units (as :meth:`Scene.render` returns them), divided by ``saturation``; a trailing
    axis of 3 or 4 channels is converted to luma likewise. Errors name ``file`` and ``key``."""
    expected = "a greyscale or RGB image, PNG or NPY"
    try:
        if path.suffix.lower() == ".npy":
            img = np.load(path, allow_pickle=False).astype(float) / saturation
        else:
            img = _read_png(path)
    except (OSError, ValueError) as e:
        raise ProblemError(file, key, expected, f"{path} ({e})") from None
    if img.ndim == 3 and img.shape[2] in (3, 4):
        img = img[..., :3] @ np.array([0.2126, 0.7152, 0.0722])
    if img.ndim != 2 or not np.isfinite(img).all():
        raise ProblemError(file, key, expected, f"{path} with shape {img.shape}")
    return img


def _read_png(path: Path) -> Array:
    """16-bit greyscale /65535, 8-bit greyscale or RGB(A) /255, 32-bit float as is; any other mode
    (bilevel, palette, …) through Pillow's conversion to 8-bit greyscale."""
    from PIL import Image

    with Image.open(path) as im:
        if im.mode in ("I;16", "I;16B", "I;16L", "I"):
            return np.asarray(im).astype(float) / 65535.0
        if im.mode == "F":
            return np.asarray(im).astype(float)
        if im.mode in ("RGB", "RGBA"):
            return np.asarray(im).astype(float) / 255.0
        return np.asarray(im.convert("L")).astype(float) / 255.0


def resize_image(img: Array, width: int, height: int, nearest: bool = False) -> Array:
    """``img`` (H, W) resampled to (height, width): bilinear, or nearest for masks."""
    if img.shape == (height, width):
        return img
    from PIL import Image

    resample = Image.Resampling.NEAREST if nearest else Image.Resampling.BILINEAR
    return np.asarray(
        Image.fromarray(img.astype(np.float32), mode="F").resize((width, height), resample), float
    )


def reference_from_image(
    scene: Scene,
    histogram: SoftHistogram,
    image: Path,
    mask: Path | None = None,
    saturation: float = 1.0,
    file: str = "<api>",
    size: tuple[int, int] | None = None,
) -> Reference:
    """A reference from an image file, sampled at the object's pixels of ``scene``.

    ``size`` (width, height): the size the image and the mask must have (the problem's camera; a
    :class:`ProblemError` with both sizes otherwise), or None to take any size. The image is then
    resized (bilinear) to ``scene``'s camera, which renders the search at a lower resolution.
    ``mask`` (non-zero = compared, resized by nearest neighbour) restricts the compared pixels to
    the object pixels it covers; the rendered image is restricted to the same pixels."""
    cam, gb = scene.camera, scene.gbuffer
    key = "objective.reference.image"
    img = _sized(read_image(image, saturation, file, key), size, image, file, key)
    img = resize_image(img, cam.width, cam.height)
    selection = None
    if mask is not None:
        key = "objective.reference.mask"
        m = _sized(read_image(mask, 1.0, file, key), size, mask, file, key)
        m = resize_image(m, cam.width, cam.height, nearest=True)
        selection = np.flatnonzero(m.ravel()[gb.pixel_index] != 0)
        if selection.size == 0:
            raise ProblemError(
                file, "objective.reference.mask", "a mask covering some object pixels", str(mask)
            )
    return reference_from_pixels(histogram, img.ravel()[gb.pixel_index], selection, f"image {image.name}")


def _sized(img: Array, size: tuple[int, int] | None, path: Path, file: str, key: str) -> Array:
    """``img`` when ``size`` (width, height) is None or its size; else a :class:`ProblemError` naming
    ``key`` with both sizes: an image of another size would be stretched to the camera's."""
    if size is not None and img.shape != (size[1], size[0]):
        raise ProblemError(
            file,
            key,
            f"an image of the camera's size, {size[0]} × {size[1]} px (camera.width × camera.height), or "
            "objective.reference.resize = true to resize it",
            f"{path.name} of {img.shape[1]} × {img.shape[0]} px",
        )
    return img


def reference_from_light(
    scene: Scene, histogram: SoftHistogram, zenith: float, azimuth: float, saturation: float = 1.0
) -> Reference:
    """A reference rendered (NumPy renderer, shadow rays) with the light at ``zenith``, ``azimuth`` (rad)."""
    pixels = scene.pixels(scene.sphere.position(zenith, azimuth)) / saturation
    label = f"light at zenith {np.rad2deg(zenith):g}°, azimuth {np.rad2deg(azimuth):g}°"
    return reference_from_pixels(histogram, pixels, None, label)


# --------------------------------------------------------------------------------------------
# The composed objective
# --------------------------------------------------------------------------------------------


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
