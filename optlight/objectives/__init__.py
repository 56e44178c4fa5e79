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

from optlight.objectives.histogram import (
    CHI2_EPS,
    EMD_SMOOTH_ABS,
    Distance,
    SoftHistogram,
    histogram_distance_casadi,
    histogram_distance_numpy,
)
from optlight.objectives.objective import Objective
from optlight.objectives.references import (
    Reference,
    read_image,
    reference_from_bins,
    reference_from_image,
    reference_from_light,
    reference_from_pixels,
    resize_image,
)
from optlight.objectives.terms import (
    DEFAULT_LEVELS,
    ContrastTerm,
    FractionTerm,
    HistogramTerm,
    ImageTerm,
    MeanTerm,
    Term,
    make_term,
)

__all__ = [
    "CHI2_EPS",
    "DEFAULT_LEVELS",
    "EMD_SMOOTH_ABS",
    "ContrastTerm",
    "Distance",
    "FractionTerm",
    "HistogramTerm",
    "ImageTerm",
    "MeanTerm",
    "Objective",
    "Reference",
    "SoftHistogram",
    "Term",
    "histogram_distance_casadi",
    "histogram_distance_numpy",
    "make_term",
    "read_image",
    "reference_from_bins",
    "reference_from_image",
    "reference_from_light",
    "reference_from_pixels",
    "resize_image",
]
