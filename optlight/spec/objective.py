"""The ``[objective]`` section: what a good image is (its terms and its reference)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

from optlight.spec.keys import key, section


@dataclass(frozen=True)
class TermSpec:
    """One weighted term of the luminance objective."""

    kind: Literal["histogram", "image", "mean", "contrast", "saturation", "shadow"] = key(
        "histogram",
        "histogram distance, image difference, mean or contrast target, saturated or shadowed fraction",
    )
    weight: float = key(1.0, "weight of the term in the sum", lo=0.0)
    distance: Literal["l2", "chi2", "emd", "emd2"] = key("emd2", "histogram distance (kind = histogram)")
    target: float | None = key(None, "target mean or standard deviation (kind = mean or contrast)", lo=0.0)
    level: float | None = key(
        None,
        "normalised luminance where a pixel counts as saturated or shadowed (default 0.98, 0.05)",
        lo=0.0,
        hi=1.0,
    )
    softness: float = key(
        0.01, "width τ of the sigmoid of the saturated or shadowed fraction", lo=0.0, lo_open=True
    )


@dataclass(frozen=True)
class ReferenceSpec:
    """What the image is compared with."""

    kind: Literal["light", "image", "bins"] = key(
        "light", "render at a reference light, read an image, or take given bins"
    )
    zenith_deg: float = key(
        10.0, "reference light zenith (kind = light; the paper uses 10°)", unit="deg", lo=0.0, hi=90.0
    )
    azimuth_deg: float = key(0.0, "reference light azimuth (kind = light)", unit="deg")
    image: str | None = key(None, "reference image, PNG or NPY (kind = image)")
    mask: str | None = key(None, "mask image of the pixels to compare, non-zero = used (kind = image)")
    resize: bool = key(
        False,
        "resize an image or mask of another size than the camera's to it (bilinear; nearest for the mask); "
        "false: such a file is refused",
    )
    bins: tuple[float, ...] | None = key(
        None, "reference histogram (kind = bins), renormalised to sum 1", lo=0.0
    )


@dataclass(frozen=True)
class ObjectiveSpec:
    """The luminance objective: a weighted sum of terms against one reference."""

    terms: tuple[TermSpec, ...] = key((TermSpec(),), "the terms, as [[objective.terms]] tables")
    bins: int = key(32, "number K of histogram bins on [0, 1]", lo=2, hi=1024)
    sigma_bins: float = key(
        1.0, "Gaussian kernel σ of the soft histogram, in bin widths", lo=0.0, lo_open=True
    )
    reference: ReferenceSpec = section(ReferenceSpec, "the reference")
