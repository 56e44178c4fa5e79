"""Writing camera images as PNG files."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike
from PIL import Image

from optlight.errors import OptlightError


def save_gray_png(path: str | Path, image: ArrayLike, saturation: float = 1.0) -> Path:
    """Write an (H, W) luminance image as 8-bit grey, 0 → black and ``saturation`` → white."""
    out = Path(path)
    if out.suffix.lower() != ".png":
        raise OptlightError(f"{out}: expected a .png output file")
    pixels = np.clip(np.asarray(image, float) / saturation, 0.0, 1.0)
    out.parent.mkdir(parents=True, exist_ok=True)
    Image.fromarray(np.round(pixels * 255).astype(np.uint8), mode="L").save(out)
    return out
