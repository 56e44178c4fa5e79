"""Robot-cell design: where to bolt the robot (and put the camera) so that it reaches the most lights.

A *cell spec* (TOML) names a base problem, the lights to reach and the ranges to search::

    description = "where to put the panda"
    problem = "default"          # a built-in name, or a path relative to this file
    lights = "landmarks"         # the base problem's landmarks, or [[zenith_deg, azimuth_deg], ...]
    method = "coarse_to_fine"    # or "grid"
    steps = 5                    # values per searched axis (per level)
    levels = 3                   # coarse_to_fine: each level halves the window, around the best so far
    top = 3                      # best placements solved in full for their acquisition time
    preview = false              # preview.html in best_plan/

    [search]                     # [low, high] in the world frame; an axis left out keeps the problem's
    base_x_m = [-0.15, 0.15]     # robot.base_position_m[0]
    base_y_m = [-0.15, 0.15]     # robot.base_position_m[1]
    # base_z_m, base_yaw_deg (robot.base_rpy_deg[2]), camera_x_m, camera_y_m, camera_z_m

**Score of a placement.** The lights are zenith/azimuth pairs on the light sphere (the landmarks are
found once, :func:`~optlight.planning.landmarks.find_landmarks` on the base problem; the sphere's
frame follows the camera, so moving the camera moves them with it). For each placement, its problem
is built (:meth:`Setup.from_problem`) and each light is tried in azimuth order with the placement
policy (:meth:`~optlight.planning.policy.Reacher.attempt`: the IK, then with ``[environment]`` a
clear posture), warm-started from the previous light's joint angles, then from the robot's reference
posture. At the joint angles found, the exact view and beam check
(:func:`~optlight.environment.view.view_check_for`: rays from the camera to the object and from the
light to the object against the robot's collision meshes and the light housing) says whether the
capture would be clear. The score is the fraction of the lights reached with the view and the beam
clear. It is what the IK's posture gives, so a lower bound: another posture of a redundant arm may be
clear where this one is not. Ties are broken by the lights where no robot link blocks a ray (the
light's own housing may: a light near the camera axis is in the view whatever the placement), then by
the lights reached. A placement whose problem is invalid (the camera inside the light sphere,
not seeing the object) scores 0 with its error.

**Search.** ``grid``: every combination of ``steps`` values per searched axis. ``coarse_to_fine``:
that grid, then at each level L = 1 … ``levels − 1`` a grid of ``steps`` values per axis over a
window half as wide as the previous level's (2^−L of the range), centred on the best placement so far
and shifted to stay inside the range (new points only). Each placement is one task on the batch
engine (:mod:`optlight.batch`: a local Dask cluster, or a remote scheduler).

**Then the acquisition time.** The placements with the best score (at most ``top``, the most lights
reached first) are solved in full (``optlight.solve``, on the engine); the best is the one whose plan
verifies with the shortest ``plan.trajectory.duration``. Its problem is written as a problem file
(``best_problem.toml``; paths in it made absolute) and its plan as ``best_plan/``.

Written into ``OUT``: ``cell_heatmap.png`` (the score over the first two searched axes, the best over
any others; finer levels as dots), ``candidates.csv`` (every placement), ``cell.json`` (the summary)
and ``best_problem.toml``, ``best_plan/``.
"""

from optlight.cell.outputs import Candidate, CellResult, heatmap_figure, write_cell
from optlight.cell.problem_toml import PATH_KEYS, problem_toml
from optlight.cell.scoring import evaluate_placement, landmark_lights
from optlight.cell.search import design_cell, level_grid, placement_problem
from optlight.cell.spec import AXES, CellSpec, cell_spec_from_dict, load_cell_spec

__all__ = [
    "AXES",
    "PATH_KEYS",
    "Candidate",
    "CellResult",
    "CellSpec",
    "cell_spec_from_dict",
    "design_cell",
    "evaluate_placement",
    "heatmap_figure",
    "landmark_lights",
    "level_grid",
    "load_cell_spec",
    "placement_problem",
    "problem_toml",
    "write_cell",
]
