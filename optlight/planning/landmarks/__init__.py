"""Landmarks (paper Section 4, docs/design.md §5): where on the light sphere the light should go.

Azimuth mode (the paper's). For ``M`` equally spaced azimuths ``φ_j = 2πj/M`` find

    θ_j* = argmin_{θ ∈ [θ_min, θ_max]} D(θ, φ_j),

``D`` the problem's objective (:class:`optlight.objectives.Objective`) of the image rendered with the
light at ``a(θ, φ_j)``. ``D`` is multimodal in θ, so per azimuth:

1. *sweep*: ``D`` at the zeniths ``θ_min, θ_min + Δ, …, θ_max`` (``Δ ≤ sweep_step_deg``), NumPy
   renderer with shadow rays at every sample (one ray-caster call per azimuth; the pole θ = 0,
   one light for every azimuth, rendered once);
2. *seeds*: the ``seeds`` lowest local minima of the sweep;
3. *refine*: per seed, a bounded Brent search (:class:`ZenithSearch`) of ``D`` over the seed's
   bracket, the zeniths between its two sweep neighbours, with the cast shadows ``v`` a fixed
   visibility mask: shadow rays at the seed; when the mask at the solution differs from the one
   searched with, the search runs again with the mask there (at most :data:`VISIBILITY_ROUNDS`
   searches per seed). ``D`` is a smooth function of θ on a bracket of a sweep minimum once the mask
   is fixed, so a derivative-free 1-D search converges in ~10 renders. A seed on an end of the
   allowed zeniths that ``D`` rises from (``D`` at :data:`REFINE_TOL` inside, mask fixed, above the
   seed's) is not searched: the search would end on it within its tolerance (the default face's
   landmarks lie on the view's boundary, so skipping those seeds saves a tenth of its search);
4. *select*: the best sweep sample and the refined zeniths are scored with the NumPy renderer and
   shadow rays; the lowest wins, so the landmark is never worse than the best sweep sample;
5. *polish* (only when the search resolution is below the camera's): one parabolic step of the
   objective at the camera's resolution around the winner (mask fixed there, three points
   :data:`POLISH_STEP` apart and the parabola's vertex), then the sweep sample, the winner and the
   polish's points are scored at the camera's resolution and the lowest is the landmark. This
   removes what the lower resolution shifts the minimiser by (~0.1–0.2° on the default face).

Why not an NLP per seed, or one batched solve across azimuths: a render and its objective are
compute-bound NumPy (the P×K histogram kernel), so batching evaluations across azimuths saves only
Python overhead, while each IPOPT solve of the 1-D NLP cost ~8 iterations of a CasADi graph three
times slower to evaluate than the NumPy objective, with its gradient. Measured on the default face
(``benchmarks/bench_landmarks.py``): the time goes to the sweep's shadow rays and to the
camera-resolution work, which the steps above keep to a few renders per azimuth.

Free mode. The ``count`` best light positions on the allowed cap, pairwise at least
``min_separation_deg`` apart: a 2-D sweep over a (θ, φ) grid, then greedily, best sample first,
each sample farther than the separation from every accepted landmark is refined by the 2-D NLP
``min_{θ,φ} D̃`` with the separation constraints ``d(θ, φ)·d_k ≤ cos(min_separation)`` to the
accepted directions ``d_k`` (constraints of unused slots are switched off through their bounds,
so this NLP too is built once) and the better of sample and refined point, scored at the camera's
resolution, is accepted (no polish). The grid has zeniths as above and azimuths at most
``sweep_step_deg`` apart; landmarks come best first.

Resolution. The search (sweeps, NLPs, candidate scores) renders at ``landmarks.resolution`` (the
longer image side, the camera's aspect kept; the camera's own resolution when that is smaller); the
reported costs and histograms use the camera's resolution. The soft histogram of a downsampled image
is close to the full-resolution one, so the minimisers move little (step 5 takes care of the rest)
while every evaluation gets cheaper by the pixel ratio (default 64 px against the 256² camera: 16×).

Modules: :mod:`~optlight.planning.landmarks.types` (the landmark types),
:mod:`~optlight.planning.landmarks.sweep` (steps 1–2), :mod:`~optlight.planning.landmarks.refinement`
(the 1-D search and the 2-D NLP), :mod:`~optlight.planning.landmarks.search` (steps 3–5, the search
scene), :mod:`~optlight.planning.landmarks.find` (the two modes). This package re-exports their public
names.

Angles are radians in code, degrees only in reports. Lengths are metres.
"""

from __future__ import annotations

from optlight.planning.landmarks.find import (
    distinct_landmarks,
    find_landmarks,
)
from optlight.planning.landmarks.refinement import (
    REFINE_TOL,
    CapRefiner,
    ZenithSearch,
)
from optlight.planning.landmarks.sweep import (
    exact_cost,
    local_minima,
    sweep_costs,
    zenith_grid,
)
from optlight.planning.landmarks.types import (
    CostGrid,
    Landmark,
    LandmarkSet,
    Progress,
)

__all__ = [
    "CapRefiner",
    "CostGrid",
    "Landmark",
    "LandmarkSet",
    "Progress",
    "REFINE_TOL",
    "ZenithSearch",
    "distinct_landmarks",
    "exact_cost",
    "find_landmarks",
    "local_minima",
    "sweep_costs",
    "zenith_grid",
]
