"""Light sets (docs/design.md §10): objectives that score N lights together, and their design.

A light set is N unit directions ``d_i`` from the object centre O towards the lights, in the light
sphere's frame S (docs/design.md §2: ``z_S`` towards the camera, so zenith 0 is frontal light). The decision
variables are the angles ``x = (θ_1 … θ_N, φ_1 … φ_N)`` (rad) with
``d_i = (sinθ_i cosφ_i, sinθ_i sinφ_i, cosθ_i)``, each zenith on the allowed cap
``θ_min ≤ θ_i ≤ θ_max`` (:class:`Cap`). ``D`` is the N×3 matrix whose rows are the ``d_i``.

Set terms (each a :class:`SetTerm`: a NumPy twin ``numpy(D, p)`` and a CasADi expression
``casadi(D, p)`` of an N×3 MX, with parameters ``p`` that are held fixed during a solve and recomputed
between solves, as the landmark search does with its visibility mask):

- :class:`UnshadowedTrace`: ``tr((DᵀD)⁻¹)``, the expected squared error of a Lambertian normal
  (times albedo) per unit noise for distant unit lights that all light the point. Since
  ``tr(DᵀD) = N``, ``tr((DᵀD)⁻¹) ≥ 9/N`` (arithmetic–harmonic means of its eigenvalues), with equality
  iff ``DᵀD = (N/3) I``: e.g. a ring at slant ``arccos(1/√3) = 54.7356°``.
- :class:`PhotometricStereoTerm`: the same per object pixel ``p`` over the lights that really light
  it, ``(1/P) Σ_p tr((D_pᵀ W_p D_p + εI)⁻¹)``, ``W_p = diag(w_p1 … w_pN)`` with the smooth weight

      w_pi = v_pi · S(β n_p·d_i) · S((ℓ − u_pi)/τ),

  ``n_p`` the G-buffer normal (sphere frame), ``v_pi ∈ {0, 1}`` the cast-shadow visibility (shadow
  rays; the parameters), ``S(x) = ½(1 + tanh(x/2))`` the logistic sigmoid, ``β`` the light's
  ``softplus_sharpness`` (attached shadow: ``n·d > 0``), and
  ``u_pi = g ρ_p (E v_pi softplus_β(n_p·d_i) + k_amb) / s`` the pixel's normalised luminance under
  light i (the smooth model of :mod:`optlight.scene.luminance` before its clip), so the weight falls
  to 0 where the pixel saturates (level ``ℓ``, width ``τ``). ``ε`` keeps pixels lit by fewer than
  three lights finite (their trace is then about ``1/ε``). The lights are taken as distant
  (directional model; for a point light ``d_i`` is the direction from O, the far-field
  approximation). Vectorised over pixels: ``C = N_S Dᵀ`` (P×N), ``W`` (P×N), the six entries
  ``m_ab = W (D_a ∘ D_b)`` (P×1) and the trace of the inverse in closed form,
  ``tr(M⁻¹) = (cof_00 + cof_11 + cof_22) / det M``.
- :class:`RieszEnergy`: even coverage for RTI, the mean over pairs of ``|d_i − d_j|^{−s}``. For
  ``s > 2`` (hypersingular on the 2-sphere) minimal-energy points are asymptotically uniformly
  distributed on the set (Hardin & Saff, "Discretizing manifolds via minimum energy points",
  Notices AMS 51(10), 2004), so the default is ``s = 4``; :func:`coverage` reports the max-min
  separation and the covering radius of a set.
- :class:`ImageSetTerm`: an image objective (:class:`optlight.objectives.Objective`) applied to
  each light and averaged, ``(1/N) Σ_i J(a(d_i), v_i)``.
- :class:`SetCost`: ``Σ_k w_k · term_k``, itself a set term.

Design. :class:`LightSetDesigner` builds the NLP ``min_x cost(D(x); p)`` s.t. the cap bounds and an
optional extra inequality ``allowed(D) ≤ 0`` (the hook for the view-excluded region and reach) once;
:func:`design_light_set` solves it from several random starts (uniform on the cap's area) and keeps
the best. :func:`design_ring` optimises the slant of an N-light ring, the classical baseline.

Grids. :func:`yale_b_grid` is the Extended Yale B list of 64 flash directions (package data);
:func:`read_grid_file` reads another; :func:`map_grid` maps each grid direction to the nearest
allowed light (a callable or a boolean mask over candidate directions), reporting every replacement.

Modules: :mod:`~optlight.planning.lightsets.directions` (the cap, coverage),
:mod:`~optlight.planning.lightsets.cost` (set terms and costs),
:mod:`~optlight.planning.lightsets.photometric_stereo` and :mod:`~optlight.planning.lightsets.rti`
(the terms of each kind), :mod:`~optlight.planning.lightsets.design` (the NLP),
:mod:`~optlight.planning.lightsets.grid` and :mod:`~optlight.planning.lightsets.replacement` (given
grids and their allowed replacements), :mod:`~optlight.planning.lightsets.problem` (from a problem
file). This package re-exports their public names.

Angles are radians in code, degrees only in files and reports.
"""


from __future__ import annotations

from optlight.planning.lightsets.cost import (
    ImageSetTerm,
    NoParameters,
    SetCost,
    SetTerm,
)
from optlight.planning.lightsets.design import (
    CLASSICAL_SLANT,
    DESIGN_SOLVER,
    PARAMETER_ROUNDS,
    RING_SWEEP,
    AllowedHook,
    LightSetDesigner,
    LightSetResult,
    check_in_cap,
    design_light_set,
    design_ring,
)
from optlight.planning.lightsets.directions import (
    Array,
    Cap,
    angles_of,
    casadi_directions,
    coverage,
    covering_radius,
    min_separation,
    ring_directions,
)
from optlight.planning.lightsets.grid import (
    Grid,
    camera_axis_direction,
    grid_from_degrees,
    read_grid_file,
    yale_b_grid,
)
from optlight.planning.lightsets.photometric_stereo import (
    DEFAULT_REGULARIZATION,
    PhotometricStereoTerm,
    UnshadowedTrace,
    Visibility,
)
from optlight.planning.lightsets.problem import (
    SAME_DIRECTION_RAD,
    grid_from_problem,
    set_cost_from_problem,
)
from optlight.planning.lightsets.replacement import (
    GridMapping,
    map_grid,
)
from optlight.planning.lightsets.rti import (
    DEFAULT_RIESZ_EXPONENT,
    RieszEnergy,
)

__all__ = [
    "AllowedHook",
    "Array",
    "CLASSICAL_SLANT",
    "Cap",
    "DEFAULT_REGULARIZATION",
    "DEFAULT_RIESZ_EXPONENT",
    "DESIGN_SOLVER",
    "Grid",
    "GridMapping",
    "ImageSetTerm",
    "LightSetDesigner",
    "LightSetResult",
    "NoParameters",
    "PARAMETER_ROUNDS",
    "PhotometricStereoTerm",
    "RING_SWEEP",
    "RieszEnergy",
    "SAME_DIRECTION_RAD",
    "SetCost",
    "SetTerm",
    "UnshadowedTrace",
    "Visibility",
    "angles_of",
    "camera_axis_direction",
    "casadi_directions",
    "check_in_cap",
    "coverage",
    "covering_radius",
    "design_light_set",
    "design_ring",
    "grid_from_degrees",
    "grid_from_problem",
    "map_grid",
    "min_separation",
    "read_grid_file",
    "ring_directions",
    "set_cost_from_problem",
    "yale_b_grid",
]
