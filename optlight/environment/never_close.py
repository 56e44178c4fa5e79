"""Self pairs that can never come close (docs/design.md §8): the body pairs of a
:class:`~optlight.environment.collision.CollisionModel` whose relative pose depends on at most
:data:`NEVER_JOINTS` joints and whose exact distance stays beyond the self margin at every angle of
those joints, proven by branch and bound (MoveIt's "Never" pairs). They are checked exactly but get
no sphere rows: spheres that contain two such bodies may overlap at every posture.
"""

from __future__ import annotations

import hashlib
from typing import TYPE_CHECKING

import numpy as np
import pinocchio as pin
import trimesh

from optlight.cache import cached_arrays

if TYPE_CHECKING:
    from optlight.environment.collision import Body, CollisionModel

#: Self pairs whose relative pose depends on at most this many joints are swept over those joints for
#: a margin they can never break (:func:`never_close_pairs`).
NEVER_JOINTS = 2
#: Finest box width (deg) of that sweep's branch and bound: a pair it has not decided then may come close.
NEVER_STEP_DEG = 0.5
#: Changed whenever what :func:`never_close_pairs` computes changes (its disk cache).
_NEVER_VERSION = 1


def never_close_pairs(
    model: CollisionModel, body_of: dict[int, Body], surfaces: list[trimesh.Trimesh]
) -> tuple[tuple[str, str], ...]:
    """Body pairs of ``model``'s self pairs that can never come within ``self_margin`` (sorted names).

    The relative pose of geometries a and b, one on an ancestor joint of the other's, depends only
    on the k joints between them. For k ≤ :data:`NEVER_JOINTS`, over a whole turn of each (wider
    than any revolute limit; the other joints at θ_ref) :func:`_clear_everywhere` proves the exact
    distance above the margin or finds where it may not be. A body pair is listed when all its
    geometry pairs are proven. Prismatic joints in between leave the pair out. Each verdict
    depends only on the two shapes (``surfaces``), the joints between and the margin, and is kept
    in the disk cache (:mod:`optlight.cache`). Ends with the geometry placed at θ_ref."""
    robot = model.robot
    verdict: dict[tuple[str, str], bool] = {}
    for pair in model.pairs:
        key = ordered_pair(pair.first_body, pair.second_name)
        if pair.kind != "self" or not verdict.get(key, True):
            continue
        between = _joints_between(model, int(body_of[pair.first].joint), int(body_of[pair.second].joint))
        verdict[key] = (
            between is not None
            and len(between) <= NEVER_JOINTS
            and all(model.travel(j) == 0.0 for j in between)
            and _cached_clear(model, pair.first, pair.second, between, surfaces)
        )
    pin.updateGeometryPlacements(
        robot.model, robot.data, model.geometry, model.geometry_data, robot.to_pin(robot.theta_ref)
    )
    return tuple(sorted(k for k, never in verdict.items() if never))


def _cached_clear(
    model: CollisionModel, a: int, b: int, between: list[int], surfaces: list[trimesh.Trimesh]
) -> bool:
    """:func:`_clear_everywhere` of geometries ``a`` and ``b`` over the joints ``between``,
    through the disk cache (keyed by the shapes, the joints' placements and kinds, the margin)."""
    joints = model.robot.model
    digest = hashlib.sha256(f"never-close {_NEVER_VERSION} {NEVER_STEP_DEG} {model.self_margin!r}".encode())
    for g in (a, b):
        digest.update(np.ascontiguousarray(surfaces[g].vertices, float).tobytes())
        digest.update(np.ascontiguousarray(model.geometry.geometryObjects[g].placement.homogeneous).tobytes())
    for j in between:
        digest.update(joints.joints[j].shortname().encode())
        digest.update(np.ascontiguousarray(joints.jointPlacements[j].homogeneous).tobytes())
    index = [joints.joints[j].idx_v for j in between]
    found = cached_arrays(
        "never_close",
        digest.hexdigest(),
        lambda: {"clear": np.array(_clear_everywhere(model, a, b, index))},
    )
    return bool(found["clear"])


def _clear_everywhere(model: CollisionModel, a: int, b: int, index: list[int]) -> bool:
    """Whether geometries ``a`` and ``b`` stay beyond ``self_margin`` for every value of the
    revolute joint angles θ[index] in [−π, π)ᵏ: branch and bound over boxes of those angles. At a
    box's centre the exact distance is d; within its half-widths w_i a point of either geometry
    moves at most Σ_i ρ_i w_i (:attr:`CollisionModel.motion_weights`), so d − Σ_i ρ_i w_i > margin clears the
    box, d ≤ margin refutes, and a box neither decides is cut in 2ᵏ, down to half-widths of
    :data:`NEVER_STEP_DEG` / 2 (then it counts as refuted)."""
    robot = model.robot
    rho = model.motion_weights[[a, b]][:, index].max(axis=0)
    smallest = np.radians(NEVER_STEP_DEG) / 2
    half = np.pi / 4
    starts = np.arange(-np.pi + half, np.pi, 2 * half)
    boxes = [
        (np.array(c), half)
        for c in np.stack(np.meshgrid(*[starts] * len(index), indexing="ij"), -1).reshape(-1, len(index))
    ]
    corners = np.stack(np.meshgrid(*[[-0.5, 0.5]] * len(index), indexing="ij"), -1).reshape(-1, len(index))
    while boxes:
        center, half = boxes.pop()
        theta = robot.theta_ref.copy()
        theta[index] = center
        q = robot.to_pin(theta)
        pin.forwardKinematics(robot.model, robot.data, q)
        for g in (a, b):
            model.geometry_data.oMg[g] = robot.data.oMi[model.geometry.geometryObjects[g].parentJoint] * (
                model.geometry.geometryObjects[g].placement
            )
        d = model.distance(a, b)
        if d <= model.self_margin:
            return False
        if d - float(rho.sum()) * half > model.self_margin:
            continue
        if half / 2 < smallest:
            return False
        boxes += [(center + half * c, half / 2) for c in corners]
    return True


def _joints_between(model: CollisionModel, a: int, b: int) -> list[int] | None:
    """The joints after the ancestor of joints ``a`` and ``b`` up to the other (both on one chain),
    which alone move one relative to the other; None when neither is the other's ancestor."""
    chain_a, chain_b = model.chain(a), model.chain(b)
    if a == 0 or a in chain_b:
        return [j for j in chain_b if j not in chain_a]
    if b == 0 or b in chain_a:
        return [j for j in chain_a if j not in chain_b]
    return None


def ordered_pair(a: str, b: str) -> tuple[str, str]:
    """The body-name pair in sorted order (a key for either order)."""
    return (a, b) if a <= b else (b, a)
