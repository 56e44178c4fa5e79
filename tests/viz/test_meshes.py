"""Display meshes (optlight.viz.meshes): the decimated robot meshes keep their shape, frame, colours
and normals against the meshes pinocchio loads; the disk cache; the compact packing."""

from __future__ import annotations

import coal
import numpy as np
import pytest
import trimesh
from scipy.spatial import cKDTree
from test_preview import packed_array

from optlight.cache import cache_folder
from optlight.robot import load_robot
from optlight.viz import meshes
from optlight.viz.meshes import CompactMeshGeometry, decimate, display_mesh


@pytest.fixture(scope="module")
def panda_visual():
    return load_robot("panda").geometry_model("visual")


def pinocchio_surface(obj) -> trimesh.Trimesh:
    """The mesh of a geometry object as pinocchio reads it (coal's loader: assimp, into a BVH), with
    the mesh scale applied: a reader of the file independent of trimesh's."""
    bvh = coal.MeshLoader().load(obj.meshPath, np.asarray(obj.meshScale, float))
    vertices = np.array(bvh.vertices())
    faces = np.array([[t[0], t[1], t[2]] for t in (bvh.tri_indices(i) for i in range(bvh.num_tris))])
    return trimesh.Trimesh(vertices, faces, process=False)


def distances(a: trimesh.Trimesh, b: trimesh.Trimesh, n: int = 100_000) -> tuple[np.ndarray, np.ndarray]:
    """Distances (m) from points sampled on each surface to the points sampled on the other (the
    sampling adds up to about half its spacing, ~0.5 mm here)."""
    pa, pb = a.sample(n, seed=0), b.sample(n, seed=1)
    return cKDTree(pb).query(pa)[0], cKDTree(pa).query(pb)[0]


@pytest.mark.slow
def test_decimated_panda_meshes_stay_close_to_the_originals(panda_visual):
    """Each Panda mesh, from 600–22,000 triangles down to at most ~4,000: the same bounding box
    within 2 mm (so the same frame: the files are Z-up COLLADA with node transforms), 99 % of either
    surface within 3 mm of the other and all of it within 12 mm (a few thin trims lose more)."""
    for obj in panda_visual.geometryObjects:
        original = pinocchio_surface(obj)
        mesh = display_mesh(obj.meshPath, scale=obj.meshScale)
        shown = trimesh.Trimesh(mesh.vertices, mesh.faces, process=False)
        assert len(mesh.faces) <= min(len(original.faces), 4000), obj.name
        np.testing.assert_allclose(shown.bounds, original.bounds, atol=2e-3, err_msg=obj.name)
        for d in distances(original, shown):
            assert np.percentile(d, 99) <= 3e-3 and d.max() <= 12e-3, (obj.name, np.percentile(d, 99), d.max())


def test_decimated_meshes_keep_colours_and_normals(panda_visual):
    """link6 is white with dark grey parts: the dark share of its area is kept (from the file's
    materials, read by trimesh), and the normals sent are unit and face the way the original
    surface does (at the faces' centres, median under 5° off the nearest original face's normal, and
    under 2 % turned away)."""
    obj = next(o for o in panda_visual.geometryObjects if o.name == "panda_link6_0")
    parts = trimesh.load(obj.meshPath).dump()
    dark_area = sum(p.area for p in parts if np.asarray(p.visual.material.baseColorFactor)[0] < 100)
    mesh = display_mesh(obj.meshPath)
    shown = trimesh.Trimesh(mesh.vertices, mesh.faces, process=False)
    face_dark = mesh.colors[mesh.faces[:, 0], 0] < 0.4
    assert shown.area_faces[face_dark].sum() / shown.area == pytest.approx(dark_area / sum(p.area for p in parts), abs=0.02)
    assert set(np.round(mesh.colors[:, 0], 2)) >= {0.25, 1.0}

    np.testing.assert_allclose(np.linalg.norm(mesh.normals, axis=1), 1.0, atol=1e-6)
    # the shading normal at each face's centre against the original face nearest to it
    original = pinocchio_surface(obj)
    at_centre = mesh.normals[mesh.faces].sum(axis=1)
    at_centre /= np.linalg.norm(at_centre, axis=1, keepdims=True)
    nearest = cKDTree(original.triangles_center).query(shown.triangles_center)[1]
    angle = np.degrees(np.arccos(np.clip(np.einsum("ij,ij->i", at_centre, original.face_normals[nearest]), -1, 1)))
    assert np.median(angle) < 5.0 and np.mean(angle > 90.0) < 0.02, (np.median(angle), np.mean(angle > 90.0))


def test_colour_given_overrides_the_materials(panda_visual):
    path = panda_visual.geometryObjects[0].meshPath
    mesh = display_mesh(path, color=(0.62, 0.66, 0.72, 1.0))
    np.testing.assert_allclose(mesh.colors, np.tile([0.62, 0.66, 0.72], (len(mesh.vertices), 1)))


def test_display_meshes_are_cached_on_disk(panda_visual, tmp_path, monkeypatch):
    finger = next(o for o in panda_visual.geometryObjects if "finger" in o.name).meshPath
    monkeypatch.setenv("OPTLIGHT_CACHE", str(tmp_path))
    meshes._display_mesh.cache_clear()
    first = display_mesh(finger)
    (cached,) = (tmp_path / "meshes").glob("*.npz")

    def fail(*args, **kwargs):
        raise AssertionError("computed again instead of read from the cache")

    monkeypatch.setattr(meshes, "_build_display_mesh", fail)
    meshes._display_mesh.cache_clear()  # a new process: only the disk remembers
    again = display_mesh(finger)
    np.testing.assert_array_equal(again.vertices, first.vertices)
    np.testing.assert_array_equal(again.faces, first.faces)
    with pytest.raises(ValueError):
        again.vertices[0, 0] = 1.0  # shared: read-only

    # other arguments are another entry; OPTLIGHT_CACHE empty turns the disk cache off
    monkeypatch.undo()
    monkeypatch.setenv("OPTLIGHT_CACHE", str(tmp_path))
    display_mesh(finger, max_faces=100)
    assert len(list((tmp_path / "meshes").glob("*.npz"))) == 2
    monkeypatch.setenv("OPTLIGHT_CACHE", "")
    assert cache_folder("meshes") is None
    cached.write_bytes(b"not an npz")  # a damaged file is computed again and replaced
    monkeypatch.setenv("OPTLIGHT_CACHE", str(tmp_path))
    meshes._display_mesh.cache_clear()
    np.testing.assert_array_equal(display_mesh(finger).faces, first.faces)
    meshes._display_mesh.cache_clear()


def test_decimate_keeps_a_sphere_round():
    sphere = trimesh.creation.icosphere(subdivisions=5, radius=0.1)  # 20,480 faces
    vertices, faces = decimate(sphere.vertices, sphere.faces, 1000)
    assert 900 <= len(faces) <= 1000
    np.testing.assert_allclose(np.linalg.norm(vertices, axis=1), 0.1, rtol=0.02)  # quadric-optimal: a bit outside
    assert trimesh.Trimesh(vertices, faces).is_watertight
    same = decimate(sphere.vertices, sphere.faces, 30_000)  # under the budget: kept
    assert len(same[1]) == len(sphere.faces)


def test_compact_geometry_packs_small_types():
    vertices = np.random.default_rng(0).normal(size=(10, 3))
    faces = np.array([[0, 1, 2], [2, 3, 9]])
    colors = np.linspace(0.0, 1.0, 30).reshape(10, 3)
    normals = vertices / np.linalg.norm(vertices, axis=1, keepdims=True)
    data = CompactMeshGeometry(vertices, faces, colors, normals).lower({})["data"]
    attributes = data["attributes"]
    assert [attributes[k]["type"] for k in ("position", "color", "normal")] == ["Float32Array", "Uint8Array", "Int8Array"]
    assert data["index"]["type"] == "Uint16Array"
    np.testing.assert_allclose(packed_array(attributes["position"]), vertices, rtol=1e-6)
    np.testing.assert_allclose(packed_array(attributes["color"]), colors, atol=0.5 / 255 + 1e-9)
    np.testing.assert_allclose(packed_array(attributes["normal"]), normals, atol=0.5 / 127 + 1e-9)
    np.testing.assert_array_equal(packed_array(data["index"]).reshape(-1, 3), faces)
    many = np.zeros((70_000, 3))
    big = CompactMeshGeometry(many, [[0, 1, 69_999]]).lower({})["data"]
    assert big["index"]["type"] == "Uint32Array" and "color" not in big["attributes"]
    with pytest.raises(ValueError, match="colours"):
        CompactMeshGeometry(vertices, faces, colors[:5])
