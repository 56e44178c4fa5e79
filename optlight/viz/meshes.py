"""Meshes for display: read with their colours, decimated to a face budget, packed compactly.

The preview inlines every mesh in one HTML file, so what it draws is sized for a screen rather than
for collision checking: a robot's CAD meshes (the Panda's visual meshes hold 134,000 triangles, 15 MB
of the page as COLLADA text) are decimated by quadric edge collapse (:func:`decimate`) to about
:data:`ROBOT_MESH_FACES` triangles per mesh file, keep their material colours and the original
surface's normals (:func:`display_mesh`), and are packed with 8-bit colours and normals and 16-bit
indices where they fit (:class:`CompactMeshGeometry`): 0.9 MB for the Panda.

Decimating the Panda's meshes takes about 2.5 s, so :func:`display_mesh` keeps each result in memory
and on disk (:func:`optlight.cache.cached_arrays`), keyed by the file's path, size and modification time: only the
first preview of a robot on a machine pays it.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import Any

import fast_simplification
import meshcat.geometry as mg
import numpy as np
import trimesh
import umsgpack
from numpy.typing import ArrayLike, NDArray
from scipy.spatial import cKDTree

from optlight.cache import cached_arrays

Array = NDArray[np.float64]

#: Triangles per robot mesh file on display (a Panda link has 12,000–22,000 in its visual mesh): at
#: 3,000 the Panda's links stay within about 2 mm of their CAD surface (99 % of it).
ROBOT_MESH_FACES = 3000
#: Triangles a part of a mesh file (a COLLADA node) keeps at least, or all it has: its share of
#: :data:`ROBOT_MESH_FACES` would flatten a thin part (a trim ring) first.
PART_MIN_FACES = 200
#: Faces meeting at a larger angle (rad) are drawn with a sharp edge between them, not smoothed over.
CREASE_ANGLE = np.radians(35.0)
#: Changed whenever what :func:`display_mesh` computes changes, so that older cache files are not read.
_CACHE_VERSION = 1

#: three.js typed-array names and the msgpack extension codes meshcat's viewer decodes them from.
_TYPED_ARRAYS = {
    np.dtype(np.int8): ("Int8Array", 0x11),
    np.dtype(np.uint8): ("Uint8Array", 0x12),
    np.dtype(np.uint16): ("Uint16Array", 0x14),
    np.dtype(np.uint32): ("Uint32Array", 0x16),
    np.dtype(np.float32): ("Float32Array", 0x17),
}


@dataclass(frozen=True)
class DisplayMesh:
    """An indexed triangle mesh with a normal and a colour per vertex: ``vertices`` (V, 3) in m in
    the mesh file's frame (its scale applied), ``faces`` (F, 3) vertex indices, ``normals`` (V, 3)
    unit, ``colors`` (V, 3) RGB in [0, 1]. Vertices are split along creases (:data:`CREASE_ANGLE`), so
    that a sharp edge shades sharp. The arrays are read-only (a cached mesh is shared)."""

    vertices: Array
    faces: NDArray[np.int64]
    normals: Array
    colors: Array


class CompactMeshGeometry(mg.Geometry):
    """A meshcat ``BufferGeometry`` of an indexed mesh, packed small: positions as float32, colours
    (optional, RGB in [0, 1]) as normalized uint8, normals (optional, unit) as normalized int8 and
    indices as uint16 when every index fits, else uint32. Without normals the viewer computes them
    from the faces."""

    def __init__(
        self,
        vertices: ArrayLike,
        faces: ArrayLike,
        colors: ArrayLike | None = None,
        normals: ArrayLike | None = None,
    ) -> None:
        super().__init__()
        self.vertices = np.asarray(vertices, np.float32).reshape(-1, 3)
        self.faces = np.asarray(faces).reshape(-1, 3)
        self.colors = None if colors is None else np.asarray(colors, float).reshape(-1, 3)
        self.normals = None if normals is None else np.asarray(normals, float).reshape(-1, 3)
        for name, values in (("colours", self.colors), ("normals", self.normals)):
            if values is not None and len(values) != len(self.vertices):
                raise ValueError(f"{len(values)} {name} for {len(self.vertices)} vertices")

    def lower(self, object_data: Any) -> dict[str, Any]:
        """The three.js JSON of the geometry (meshcat's ``lower`` protocol)."""
        attributes = {"position": typed_array(self.vertices, 3)}
        if self.colors is not None:
            rgb = np.round(np.clip(self.colors, 0.0, 1.0) * 255).astype(np.uint8)
            attributes["color"] = typed_array(rgb, 3, normalized=True)
        if self.normals is not None:
            xyz = np.round(np.clip(self.normals, -1.0, 1.0) * 127).astype(np.int8)
            attributes["normal"] = typed_array(xyz, 3, normalized=True)
        index_type = np.uint16 if len(self.vertices) <= 1 << 16 else np.uint32
        return {
            "uuid": self.uuid,
            "type": "BufferGeometry",
            "data": {"attributes": attributes, "index": typed_array(self.faces.astype(index_type), 1)},
        }


def typed_array(values: NDArray[Any], item_size: int, *, normalized: bool = False) -> dict[str, Any]:
    """A three.js buffer attribute of ``values`` (int8, uint8, uint16, uint32 or float32) flattened
    row by row; ``normalized`` integers are read as [0, 1] (unsigned) or [−1, 1] (signed) by the
    viewer."""
    name, code = _TYPED_ARRAYS[values.dtype]
    data = np.ascontiguousarray(values, values.dtype.newbyteorder("<")).tobytes()
    return {"itemSize": item_size, "type": name, "array": umsgpack.Ext(code, data), "normalized": normalized}


def float32_ext(values: ArrayLike) -> umsgpack.Ext:
    """``values`` flattened row by row as a Float32Array for meshcat's viewer."""
    return umsgpack.Ext(_TYPED_ARRAYS[np.dtype(np.float32)][1], np.asarray(values, "<f4").tobytes())


def decimate(vertices: ArrayLike, faces: ArrayLike, max_faces: int) -> tuple[Array, NDArray[np.int64]]:
    """The mesh with at most about ``max_faces`` triangles: coincident vertices merged, then, when it
    has more, quadric edge collapse (Garland–Heckbert, ``fast_simplification``). Returns vertices
    (V, 3) and faces (F, 3)."""
    mesh = trimesh.Trimesh(np.asarray(vertices, float), np.asarray(faces), process=True)
    if len(mesh.faces) > max_faces:
        points, triangles = fast_simplification.simplify(mesh.vertices, mesh.faces, target_count=max_faces)
        mesh = trimesh.Trimesh(points, triangles, process=True)  # drops faces that collapsed flat
    return np.asarray(mesh.vertices, float), np.asarray(mesh.faces, np.int64)


def transfer_normals(decimated: trimesh.Trimesh, original: trimesh.Trimesh, neighbours: int = 8) -> Array:
    """Unit normals (V, 3) for the vertices of ``decimated``, taken from ``original`` (both split
    along their creases): of the ``neighbours`` original vertices nearest to each vertex, the normal
    closest to the one the decimated faces give it. A decimated surface's faces are uneven and
    normals averaged over them make it look dented; the original's are smooth, and choosing among
    them by direction keeps each side of a crease on its own side."""
    own = np.asarray(decimated.vertex_normals, float)
    k = min(neighbours, len(original.vertices))
    _, nearest = cKDTree(original.vertices).query(decimated.vertices, k=k)
    candidates = np.asarray(original.vertex_normals, float)[np.reshape(nearest, (len(own), k))]
    best = np.argmax(np.einsum("vkc,vc->vk", candidates, own), axis=1)
    return candidates[np.arange(len(own)), best]


def display_mesh(
    path: str | Path,
    *,
    scale: ArrayLike = (1.0, 1.0, 1.0),
    color: ArrayLike | None = None,
    default_color: ArrayLike = (0.8, 0.8, 0.8),
    max_faces: int = ROBOT_MESH_FACES,
) -> DisplayMesh:
    """The mesh file at ``path`` (what trimesh reads; COLLADA through pycollada) for display: each
    part (a COLLADA node, its transform applied) decimated to its share of ``max_faces`` but at
    least :data:`PART_MIN_FACES` (:func:`decimate`), split along creases, with the original
    surface's normals (:func:`transfer_normals`); coloured by ``color`` (RGB(A) in [0, 1]) when
    given, else by each part's material colour, else ``default_color``. ``scale`` (3,) multiplies
    the coordinates (the URDF's mesh scale). Cached in memory and on disk (module docstring)."""
    file = Path(path).resolve()
    stat = file.stat()
    rgb = None if color is None else tuple(np.asarray(color, float)[:3].tolist())
    args = (
        tuple(np.broadcast_to(np.asarray(scale, float), (3,)).tolist()),
        rgb,
        tuple(np.asarray(default_color, float)[:3].tolist()),
        int(max_faces),
    )
    key = repr((_CACHE_VERSION, str(file), stat.st_size, stat.st_mtime_ns, *args))
    return _display_mesh(key, file, *args)


@lru_cache(maxsize=256)
def _display_mesh(
    key: str,
    file: Path,
    scale: tuple[float, float, float],
    color: tuple[float, ...] | None,
    default_color: tuple[float, ...],
    max_faces: int,
) -> DisplayMesh:
    """:func:`display_mesh` from the disk cache, else computed and written there."""

    def compute() -> dict[str, NDArray[Any]]:
        mesh = _build_display_mesh(file, np.asarray(scale), color, default_color, max_faces)
        return {"vertices": mesh.vertices, "faces": mesh.faces, "normals": mesh.normals, "colors": mesh.colors}

    data = cached_arrays("meshes", key, compute)
    mesh = DisplayMesh(data["vertices"], data["faces"], data["normals"], data["colors"])
    for array in (mesh.vertices, mesh.faces, mesh.normals, mesh.colors):
        array.setflags(write=False)
    return mesh


def _build_display_mesh(
    file: Path,
    scale: Array,
    color: tuple[float, ...] | None,
    default_color: tuple[float, ...],
    max_faces: int,
) -> DisplayMesh:
    loaded = trimesh.load(file)
    found = loaded.dump() if isinstance(loaded, trimesh.Scene) else [loaded]
    parts = [p for p in found if isinstance(p, trimesh.Trimesh) and len(p.faces)]
    share = min(1.0, max_faces / max(sum(len(p.faces) for p in parts), 1))
    vertices, faces, normals, colors, offset = [], [], [], [], 0
    for part in parts:
        rgb = color if color is not None else _part_color(part, default_color)
        target = max(int(share * len(part.faces)), min(len(part.faces), PART_MIN_FACES))
        v, f = decimate(part.vertices * scale, part.faces, target)
        smooth = trimesh.graph.smooth_shade(trimesh.Trimesh(v, f, process=False), angle=CREASE_ANGLE)
        original = trimesh.graph.smooth_shade(
            trimesh.Trimesh(part.vertices * scale, part.faces, process=True), angle=CREASE_ANGLE
        )
        vertices.append(np.asarray(smooth.vertices, float))
        faces.append(np.asarray(smooth.faces, np.int64) + offset)
        normals.append(transfer_normals(smooth, original))
        colors.append(np.tile(np.asarray(rgb, float), (len(smooth.vertices), 1)))
        offset += len(smooth.vertices)
    if not parts:
        empty = np.zeros((0, 3))
        return DisplayMesh(empty, np.zeros((0, 3), np.int64), empty, empty)
    return DisplayMesh(np.vstack(vertices), np.vstack(faces), np.vstack(normals), np.vstack(colors))


def _part_color(part: trimesh.Trimesh, default: tuple[float, ...]) -> tuple[float, ...]:
    """RGB in [0, 1] of a part: its material's base (or diffuse) colour, its mean face colour, or
    ``default``."""
    visual = part.visual
    material = getattr(visual, "material", None)
    for name in ("baseColorFactor", "diffuse"):
        value = getattr(material, name, None)
        if value is not None:
            return tuple((np.asarray(value, float)[:3] / 255.0).tolist())
    if isinstance(visual, trimesh.visual.ColorVisuals) and visual.kind == "face":
        return tuple((np.asarray(visual.face_colors, float)[:, :3].mean(axis=0) / 255.0).tolist())
    return default
