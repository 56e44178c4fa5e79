"""Writing camera images as PNG files.

Every PNG written here carries the text chunk ``Software: optlight`` (:data:`SOFTWARE`):
``optlight render --force`` replaces only a PNG that carries it (:func:`written_by_optlight`), never a
picture of the user's.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike
from PIL import Image, PngImagePlugin

from optlight.errors import OptlightError

#: The PNG text chunk (keyword, value) that marks a file optlight wrote.
SOFTWARE = ("Software", "optlight")


def save_gray_png(path: str | Path, image: ArrayLike, saturation: float = 1.0) -> Path:
    """Write an (H, W) luminance image as 8-bit grey, 0 → black and ``saturation`` → white, marked
    with the text chunk :data:`SOFTWARE`."""
    out = Path(path)
    if out.suffix.lower() != ".png":
        raise OptlightError(f"{out}: expected a .png output file")
    pixels = np.clip(np.asarray(image, float) / saturation, 0.0, 1.0)
    out.parent.mkdir(parents=True, exist_ok=True)
    info = PngImagePlugin.PngInfo()
    info.add_text(*SOFTWARE)
    Image.fromarray(np.round(pixels * 255).astype(np.uint8), mode="L").save(out, pnginfo=info)
    return out


def written_by_optlight(path: str | Path) -> bool:
    """Whether ``path`` is a PNG file that :func:`save_gray_png` wrote (its :data:`SOFTWARE` text
    chunk); False for anything else, unreadable files included."""
    try:
        with Image.open(path) as im:
            return im.format == "PNG" and getattr(im, "text", {}).get(SOFTWARE[0]) == SOFTWARE[1]
    except (OSError, ValueError, Image.DecompressionBombError):
        return False
