"""Reading user URDFs: the parser's stderr kept out of the terminal, ``package://`` lookup, mesh files.

**User URDFs** (``robot.urdf``). Mesh files are found as ROS finds them (:func:`find_package`):
``package://NAME/rest`` is ``rest`` inside the package folder NAME, looked up in the URDF's folder
and every folder above it (nearest first: a folder named NAME, or one holding a folder NAME), then
in each folder of the ``ROS_PACKAGE_PATH`` environment variable (the folder itself when it is
named NAME, a folder NAME in it, or one up to :data:`PACKAGE_SEARCH_DEPTH` levels below it holding a
``package.xml``); ``file://`` and plain paths are files, relative ones relative to the URDF. Every
mesh must resolve when the robot is loaded; a URDF the parser rejects, a mesh that does not resolve
and a flange frame it does not have are errors naming ``robot.urdf`` or ``robot.frame``, and the
parser's own messages on stderr are kept out of the terminal (the first one is quoted in ours).
"""
from __future__ import annotations

import os
import sys
import tempfile
import xml.etree.ElementTree as ET
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path

import coal
import numpy as np
import pinocchio as pin
from numpy.typing import NDArray

from optlight.errors import ProblemError

Array = NDArray[np.float64]

#: How many folder levels below a ``ROS_PACKAGE_PATH`` entry :func:`find_package` looks for a package.
PACKAGE_SEARCH_DEPTH = 3


@contextmanager
def quiet_stderr() -> Iterator[list[str]]:
    """Send what C/C++ code writes on file descriptor 2 (urdfdom's "Error: …" lines) to a
    temporary file instead of the terminal; the yielded list holds those lines after the block."""
    said: list[str] = []
    sys.stderr.flush()
    try:
        saved = os.dup(2)
    except OSError:  # no stderr to redirect
        yield said
        return
    with tempfile.TemporaryFile(mode="w+b") as sink:
        os.dup2(sink.fileno(), 2)
        try:
            yield said
        finally:
            os.dup2(saved, 2)
            os.close(saved)
            sink.seek(0)
            said.extend(sink.read().decode(errors="replace").splitlines())


def first_error(said: Sequence[str], error: Exception) -> str:
    """The parser's first "Error:" line when it printed one, else the exception's message."""
    for line in said:
        if line.strip().startswith("Error:"):
            return f"{error} ({line.strip()[6:].strip()})"
    return str(error)


def find_package(name: str, urdf: Path) -> Path | None:
    """The folder of the ROS package ``name`` for the URDF at ``urdf``, or None.

    Looked up as ROS does, in this order: the URDF's folder and every folder above it, nearest first
    (the folder itself when it is named ``name``, else a folder ``name`` in it); then each folder of
    ``ROS_PACKAGE_PATH`` (the folder itself when it is named ``name``, a folder ``name`` in it, or a
    folder ``name`` holding a ``package.xml`` up to :data:`PACKAGE_SEARCH_DEPTH` levels below it).
    """
    for folder in (urdf.parent, *urdf.parent.parents):
        if folder.name == name:
            return folder
        if (folder / name).is_dir():
            return folder / name
    for entry in os.environ.get("ROS_PACKAGE_PATH", "").split(os.pathsep):
        if not entry:
            continue
        root = Path(entry).expanduser()
        if root.name == name and root.is_dir():
            return root
        if (root / name).is_dir():
            return root / name
        level = [root]
        for _ in range(PACKAGE_SEARCH_DEPTH):
            level = [d for f in level for d in _subfolders(f)]
            for d in level:
                if d.name == name and (d / "package.xml").is_file():
                    return d
    return None


def _subfolders(folder: Path) -> list[Path]:
    """The visible subfolders of ``folder`` (none where it cannot be read)."""
    try:
        return sorted(d for d in folder.iterdir() if d.is_dir() and not d.name.startswith("."))
    except OSError:
        return []


def resolve_mesh(filename: str, urdf: Path) -> Path | None:
    """The file a URDF ``<mesh filename=…>`` names (``package://``, ``file://`` or a path, relative
    to the URDF), or None when it does not exist."""
    if filename.startswith("package://"):
        name, _, rest = filename[len("package://") :].partition("/")
        package = find_package(name, urdf)
        path = package / rest if package is not None else None
    elif filename.startswith("file://"):
        path = Path(filename[len("file://") :])
    else:
        path = Path(filename).expanduser()
        path = path if path.is_absolute() else urdf.parent / path
    return path if path is not None and path.is_file() else None


def urdf_package_dirs(urdf: Path, file: str) -> list[Path]:
    """Check that every mesh of a user URDF resolves (module docstring); return the folders to give
    pinocchio as ``package_dirs`` (it looks for ``dir/NAME/rest``): each package's parent folder."""
    try:
        root = ET.parse(urdf).getroot()
    except (ET.ParseError, OSError, UnicodeDecodeError) as e:
        raise ProblemError(file, "robot.urdf", f"a URDF file (XML: {e})", str(urdf)) from None
    dirs: list[Path] = []
    for mesh in root.iter("mesh"):
        filename = mesh.get("filename", "")
        found = resolve_mesh(filename, urdf)
        if found is None:
            raise ProblemError(
                file,
                "robot.urdf",
                f"a URDF whose meshes exist ({filename!r} does not resolve: package://NAME is looked up in "
                "the URDF's folder and those above it, then in ROS_PACKAGE_PATH)",
                str(urdf),
            )
        if filename.startswith("package://"):
            name = filename[len("package://") :].split("/", 1)[0]
            package = find_package(name, urdf)
            assert package is not None  # resolve_mesh found the file in it
            if package.parent not in dirs:
                dirs.append(package.parent)
    return dirs


def unread_visual_meshes(model: pin.Model, urdf: Path) -> pin.GeometryModel:
    """The visual geometry of ``urdf`` as pinocchio's parser makes it (names ``<link>_<k>``, parent
    joints and frames, placements, materials, primitives), its mesh files found but not read: the
    parser is given the URDF with each visual ``<mesh>`` replaced by a point (a sphere of radius 0),
    and each of those objects then gets back the mesh's file (``meshPath``, resolved as
    :func:`resolve_mesh` does), its ``scale`` (``meshScale``) and an empty BVH as geometry, which
    meshcat viewers take for a mesh to read from its file. Raises ValueError for a mesh file that
    does not resolve."""
    root = ET.parse(urdf).getroot()
    meshes: dict[str, tuple[Path, Array]] = {}
    for link in root.findall("link"):
        for k, visual in enumerate(link.findall("visual")):
            geometry = visual.find("geometry")
            mesh = geometry.find("mesh") if geometry is not None else None
            if geometry is None or mesh is None:
                continue
            filename = mesh.get("filename", "")
            found = resolve_mesh(filename, urdf)
            if found is None:
                raise ValueError(f"the mesh {filename!r} does not resolve")
            meshes[f"{link.get('name')}_{k}"] = (found, np.array(mesh.get("scale", "1 1 1").split(), float))
            geometry.remove(mesh)
            ET.SubElement(geometry, "sphere", radius="0")
    geom = pin.buildGeomFromUrdfString(model, ET.tostring(root, encoding="unicode"), pin.GeometryType.VISUAL)
    for obj in geom.geometryObjects:
        if obj.name in meshes:
            path, scale = meshes[obj.name]
            obj.geometry, obj.meshPath, obj.meshScale = coal.BVHModelOBBRSS(), str(path), scale
    return geom
