"""The camera's response curve: recorded values Y from linear radiance I, and back.

Y = s·(clip(I, 0, s)/s)^(1/γ) with s the full-scale value (``[light] saturation``) and γ the
response's exponent (1 for a linear camera, ~2.2 for an sRGB-like one); docs/design.md §11.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

Array = NDArray[np.float64]


def respond(linear: ArrayLike, saturation: float, gamma: float) -> Array:
    """The camera response Y = s·(clip(I, 0, s)/s)^(1/γ) of linear values I."""
    u = np.clip(np.asarray(linear, float) / saturation, 0.0, 1.0)
    return saturation * u ** (1.0 / gamma)


def linearise(recorded: ArrayLike, saturation: float, gamma: float) -> Array:
    """The inverse of :func:`respond`: I = s·(Y/s)^γ, for Y in [0, s]."""
    u = np.clip(np.asarray(recorded, float) / saturation, 0.0, 1.0)
    return saturation * u**gamma
