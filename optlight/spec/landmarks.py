"""Sections of where the light goes: the landmark search and lights designed as a set."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

from optlight.spec.keys import SEED_MAX, key


@dataclass(frozen=True)
class LandmarksSpec:
    """Where the light should go (paper, Section 4)."""

    mode: Literal["azimuth", "free"] = key(
        "azimuth", "best zenith per equally spaced azimuth, or the best positions on the cap"
    )
    count: int = key(
        36,
        "number M of landmarks searched (azimuths, or free positions); landmarks within distinct_deg of "
        "each other are one capture, so a plan can have fewer captures than count",
        lo=1,
        hi=720,
    )
    min_separation_deg: float = key(
        10.0, "smallest angle between two landmarks (mode = free)", unit="deg", lo=0.0
    )
    sweep_step_deg: float = key(
        2.0,
        "zenith step of the coarse sweep that seeds the refinement (a finer sweep only multiplies the renders)",
        unit="deg",
        lo=0.1,
        hi=45.0,
    )
    seeds: int = key(3, "sweep minima refined by IPOPT per azimuth", lo=1, hi=50)
    resolution: int = key(
        64,
        "longer image side of the search renders (the camera's when smaller); reported costs use the camera's",
        unit="px",
        lo=8,
        hi=8192,
    )
    allow_partial: bool = key(False, "drop unreachable landmarks with a warning instead of failing")
    distinct_deg: float = key(
        0.5,
        "landmarks closer than this angle are one capture (the same image): the lower-cost one is kept",
        unit="deg",
        lo=0.0,
    )


@dataclass(frozen=True)
class LightSetSpec:
    """A set of N lights scored together (docs/design.md §10) instead of landmarks matched one by one:
    photometric stereo (the expected normal error of the set), RTI (even coverage of the cap) or a
    given grid (a face database's directions, each mapped to the nearest allowed light). Off
    (kind = "none") by default."""

    kind: Literal["none", "photometric_stereo", "rti", "grid"] = key(
        "none",
        "no light set (the landmarks of [landmarks]), a photometric-stereo set, an RTI dome, or a grid",
    )
    count: int = key(12, "number N of lights (photometric_stereo: at least 3; rti: at least 2)", lo=1, hi=720)
    starts: int = key(8, "random starts of the set design, uniform on the cap", lo=1, hi=1000)
    seed: int = key(0, "seed of the random starts", lo=0, hi=SEED_MAX)
    regularization: float = key(
        1e-2,
        "ε of the per-pixel M + εI (photometric_stereo): a pixel lit by fewer than 3 lights costs ~1/ε",
        lo=0.0,
        lo_open=True,
    )
    saturation_level: float = key(
        0.98,
        "normalised luminance from which a pixel counts as saturated (its light is not used)",
        lo=0.0,
        hi=1.0,
        lo_open=True,
    )
    dark_level: float = key(
        0.02,
        "normalised luminance (ambient removed) below which a pixel counts as shadowed in normal recovery",
        lo=0.0,
        hi=1.0,
    )
    softness: float = key(0.01, "width τ of the saturation sigmoid in the set cost", lo=0.0, lo_open=True)
    riesz_exponent: float = key(
        4.0, "exponent s of the Riesz energy (rti); s > 2 spreads the lights evenly", lo=0.0, lo_open=True
    )
    image_weight: float = key(
        0.0,
        "weight of the [objective] image objective, averaged over the set's lights, added to the set cost",
        lo=0.0,
    )
    grid_file: str | None = key(
        None,
        "CSV of the grid (kind = grid): columns azimuth_deg, elevation_deg relative to the camera axis "
        "[, name]; default: the 64 Yale B directions shipped with optlight",
    )
    grid_deg: tuple[tuple[float, float], ...] | None = key(
        None,
        "the grid as [azimuth_deg, elevation_deg] pairs relative to the camera axis (kind = grid)",
        unit="deg",
    )
    grid_outside_cap: Literal["replace", "error"] = key(
        "replace", "grid directions off the cap: replace by the nearest allowed light, or refuse the file"
    )
    design_over: Literal["reachable", "cap"] = key(
        "reachable",
        "map where the robot reaches the light clear first (a reachability map of the cap) and design "
        "photometric_stereo and rti sets over those lights (a grid's replacements start from the map too), "
        "or design on the whole allowed cap (lights the robot cannot reach are then replaced one by one)",
    )
    reach_step_deg: float = key(
        5.0,
        "zenith step of that reachability map (its azimuth step is twice this)",
        unit="deg",
        lo=1.0,
        hi=30.0,
    )
    candidate_spacing_deg: float = key(
        2.0,
        "spacing of the candidate lights a grid direction may be replaced by (their count grows as its "
        "inverse square)",
        unit="deg",
        lo=0.5,
        hi=30.0,
    )
