"""The folder camera: the images a real camera wrote, matched to the captures by ``captures.csv``.

The folder holds a ``captures.csv`` (as :func:`optlight.export.write_captures` writes it, from
``optlight solve`` or ``optlight acquire``) and the image files its ``image`` column names: PNG or
TIFF, 8 or 16 bit, greyscale or RGB (converted to luma), of the camera's size. A capture with the
light at a is the row whose ``light_position_*_m`` is nearest to a, within ``tolerance_m``; its file's
values x ∈ [0, 1] (full scale 255 or 65535) are linearised by the given response,
I = s·x^γ (γ = ``response_gamma``, 1 for a linear camera or a raw file), into the renderer's units.

The image files may lie in another folder than captures.csv (``images``). Everything is checked
when the camera is made, each refusal a one-line :class:`~optlight.errors.ProblemError` naming the
file: a row without an image name or with one outside the images' folder (a path separator, ``..``),
two rows naming the same image, two rows whose lights are within
2·``tolerance_m`` of each other (a capture could match either), a missing file, one of another size
than the camera's.
"""

from __future__ import annotations

import csv
import io
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray
from PIL import Image, UnidentifiedImageError

from optlight.capture import Capture
from optlight.errors import OptlightError, ProblemError
from optlight.objectives import read_image
from optlight.scene import Camera
from optlight.scene.response import linearise

#: The columns of captures.csv the folder camera reads.
POSITION_COLUMNS = ("light_position_x_m", "light_position_y_m", "light_position_z_m")


class MissingCaptureError(OptlightError):
    """No image in the folder was taken with the light where the plan puts it (e.g. a re-planned
    landmark the robot has not visited yet)."""


class FolderCamera:
    """Images of a real camera in ``folder`` (module docstring). ``camera``: the pinhole model, whose
    size every image must have; ``saturation``: s, the renderer's value of a full-scale pixel."""

    kind = "folder"

    def __init__(
        self,
        folder: str | Path,
        camera: Camera,
        saturation: float = 1.0,
        response_gamma: float = 1.0,
        tolerance_m: float = 1e-3,
        images: str | Path | None = None,
    ) -> None:
        self.folder = Path(folder)
        self.images = self.folder if images is None else Path(images)
        self.camera = camera
        self.saturation = float(saturation)
        self.response_gamma = float(response_gamma)
        self.tolerance_m = float(tolerance_m)
        self.csv = self.folder / "captures.csv"
        self.names, self.positions = read_captures_csv(self.csv)
        self._check_rows()
        for row, name in enumerate(self.names):
            self._check_file(row, name)

    def _check_rows(self) -> None:
        """Refuse rows no capture can be matched to unambiguously: no image name, a name outside the
        images' folder (a path separator, ``..``), a name two rows give, lights closer than
        ``tolerance_m``."""
        seen: dict[str, int] = {}
        for row, name in enumerate(self.names):
            if not name.strip():
                raise ProblemError(str(self.csv), "image", f"an image file name on row {row}", name)
            if any(c in name for c in "/\\") or ".." in name or name.startswith("~"):
                where = f"a file name in the images' folder on row {row} (no / \\ or ..)"
                raise ProblemError(str(self.csv), "image", where, name)
            if name in seen:
                raise ProblemError(
                    str(self.csv), "image", "one row per image file", f"{name} on rows {seen[name]} and {row}"
                )
            seen[name] = row
        gaps = np.linalg.norm(self.positions[:, None] - self.positions[None], axis=2)
        close = np.argwhere(np.triu(gaps <= 2 * self.tolerance_m, k=1))  # a light within tolerance of both
        if len(close):
            a, b = close[0]
            raise ProblemError(
                str(self.csv),
                "light_position_*_m",
                f"lights more than {2e3 * self.tolerance_m:g} mm apart (a capture matches one row)",
                f"rows {a} and {b} {1e3 * gaps[a, b]:.2g} mm apart",
            )

    def _check_file(self, row: int, name: str) -> Path:
        path = self.images / name
        if not path.is_file():
            raise ProblemError(str(path), "", f"the image file row {row} of {self.csv.name} names", "no such file")
        try:
            with Image.open(path) as im:
                size = im.size
        except (OSError, UnidentifiedImageError) as e:
            raise ProblemError(str(path), "", "a PNG or TIFF image", str(e)) from None
        expected = (self.camera.width, self.camera.height)
        if size != expected:
            raise ProblemError(
                str(path), "", f"an image of the camera's size {expected[0]}×{expected[1]} px", f"{size[0]}×{size[1]} px"
            )
        return path

    def capture(self, light_position: ArrayLike, index: int = 0, light_rotation: ArrayLike | None = None) -> Capture:
        """The image of the row nearest to ``light_position``, linearised; :class:`MissingCaptureError`
        when no row is within ``tolerance_m``."""
        a = np.asarray(light_position, float)
        distance = np.linalg.norm(self.positions - a, axis=1) if len(self.positions) else np.array([np.inf])
        row = int(np.argmin(distance))
        if not distance[row] <= self.tolerance_m:
            nearest = f"nearest {1e3 * distance[row]:.1f} mm away" if np.isfinite(distance[row]) else "no rows"
            raise MissingCaptureError(
                f"{self.csv}: no image of capture {index} (light at {np.round(a, 4).tolist()} m; {nearest})"
            )
        path = self._check_file(row, self.names[row])
        recorded = read_image(path, 1.0, str(path), "")
        exposure = {
            "camera": self.kind,
            "file": self.names[row],
            "saturation": self.saturation,
            "linearised_gamma": self.response_gamma,
        }
        linear = linearise(recorded * self.saturation, self.saturation, self.response_gamma)
        rotation = None if light_rotation is None else np.asarray(light_rotation, float).reshape(3, 3)
        return Capture(linear, a, index, exposure, rotation)


def read_captures_csv(path: Path) -> tuple[list[str], NDArray[np.float64]]:
    """The image names and light positions (N, 3, m) of a captures.csv, UTF-8 text (a byte order
    mark is skipped); errors name the file, and for text that is not UTF-8 the line and the byte."""
    if not path.is_file():
        raise ProblemError(str(path), "", "a captures.csv (as optlight solve or acquire writes it)", "no such file")
    data = path.read_bytes()
    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError as e:
        start = e.start + (3 if data.startswith(b"\xef\xbb\xbf") else 0)  # utf-8-sig reports from after the mark
        line = data.count(b"\n", 0, start) + 1
        column = start - (data.rfind(b"\n", 0, start) + 1) + 1
        raise ProblemError(
            str(path), "", "UTF-8 text", f"byte 0x{data[start]:02x} at line {line}, byte {column} of the line ({e.reason})"
        ) from None
    rows = list(csv.DictReader(io.StringIO(text, newline="")))
    columns = ("image", *POSITION_COLUMNS)
    if rows:
        missing = [c for c in columns if c not in rows[0]]
        if missing:
            raise ProblemError(str(path), missing[0], "the columns " + ", ".join(columns), "missing")
    try:
        positions = np.array([[float(r[c]) for c in POSITION_COLUMNS] for r in rows], float).reshape(-1, 3)
    except (TypeError, ValueError) as e:
        raise ProblemError(str(path), "light_position_*_m", "numbers", str(e)) from None
    return [r["image"] for r in rows], positions
