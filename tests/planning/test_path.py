"""Great-circle paths, visiting order and roll transport, against geometric truth."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from optlight.geometry import LightSphere, great_circle, h_residual, sphere_frame
from optlight.planning.path import build_path, parallel_transport_frames, shortest_open_tour

SPHERE = LightSphere(
    center=np.array([0.4, -0.2, 0.3]),
    radius=0.4,
    rotation=sphere_frame([0.4, -0.2, 0.3], [0.4, -1.0, 0.3]),
    zenith_min=0.0,
    zenith_max=np.deg2rad(60),
)


def test_sphere_coordinates_round_trip() -> None:
    rng = np.random.default_rng(0)
    zen, az = rng.uniform(0.01, 1.5, 50), rng.uniform(0, 2 * np.pi, 50)
    z2, a2 = SPHERE.angles(SPHERE.position(zen, az))
    np.testing.assert_allclose(z2, zen, atol=1e-12)
    np.testing.assert_allclose(a2, az, atol=1e-12)
    # zenith 0 points at the camera; azimuth 90° is up (y_S = world z here)
    np.testing.assert_allclose(SPHERE.direction(0.0, 0.0), [0, -1, 0], atol=1e-12)
    np.testing.assert_allclose(SPHERE.direction(np.pi / 2, np.pi / 2), [0, 0, 1], atol=1e-12)


def test_great_circle_stays_on_the_circle_with_bounded_steps() -> None:
    u, v = SPHERE.direction(0.2, 0.3), SPHERE.direction(1.0, 2.5)
    arc = great_circle(u, v, np.deg2rad(2.0))
    np.testing.assert_allclose(np.linalg.norm(arc, axis=1), 1.0, atol=1e-12)
    normal = np.cross(u, v) / np.linalg.norm(np.cross(u, v))
    np.testing.assert_allclose(arc @ normal, 0.0, atol=1e-12)  # in the plane through O, u, v
    steps = np.arccos(np.clip(np.sum(arc[1:] * arc[:-1], axis=1), -1, 1))
    assert steps.max() <= np.deg2rad(2.0) + 1e-12
    np.testing.assert_allclose(steps, steps[0], atol=1e-12)  # uniform in angle
    np.testing.assert_allclose(steps.sum(), np.arccos(u @ v), atol=1e-12)  # the shorter arc
    np.testing.assert_allclose(arc[[0, -1]], [u, v], atol=1e-12)


def test_antipodal_points_have_no_unique_arc() -> None:
    with pytest.raises(ValueError, match="antipodal"):
        great_circle([0, 0, 1], [0, 0, -1], 0.1)


def test_path_knots_land_on_landmarks_and_aim_at_the_centre() -> None:
    az = np.linspace(0, 2 * np.pi, 12, endpoint=False)
    pts = SPHERE.position(np.full(12, 0.7), az)
    path = build_path(SPHERE, pts, np.arange(12), np.deg2rad(2.0))
    np.testing.assert_allclose(path.positions[path.landmark_knots], pts, atol=1e-12)
    for p, r in zip(path.positions, path.rotations, strict=True):
        np.testing.assert_allclose(h_residual(p, r, SPHERE.center, SPHERE.radius), 0.0, atol=1e-12)
        np.testing.assert_allclose(r.T @ r, np.eye(3), atol=1e-12)
    assert len(path.segments()) == 11


def test_parallel_transport_never_flips_the_roll() -> None:
    # A full loop around the pole: x turns smoothly, consecutive frames stay close.
    az = np.linspace(0, 2 * np.pi, 361)
    dirs = SPHERE.direction(np.full_like(az, 0.5), az)
    frames = parallel_transport_frames(dirs, SPHERE.rotation[:, 0])
    dx = np.linalg.norm(np.diff(frames[:, :, 0], axis=0), axis=1)
    assert dx.max() < 0.05
    # no sign flip of the roll between knots
    assert np.all(np.einsum("ki,ki->k", frames[1:, :, 0], frames[:-1, :, 0]) > 0.99)


def test_open_tour_matches_brute_force_on_small_instances() -> None:
    rng = np.random.default_rng(3)
    for _ in range(5):
        pts = rng.uniform(-1, 1, (7, 2))
        d = np.linalg.norm(pts[:, None] - pts[None], axis=2)
        tour = shortest_open_tour(d)
        length = d[tour[:-1], tour[1:]].sum()
        best = min(d[list(p[:-1]), list(p[1:])].sum() for p in itertools.permutations(range(7)))
        assert sorted(tour) == list(range(7))
        assert length <= best * 1.05 + 1e-12
