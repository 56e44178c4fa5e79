"""Sections of the camera in the loop: how the real scene differs from the model, and the loop
itself (capture, calibrate, re-plan)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

from optlight.spec.keys import GAMMA_RANGE, SEED_MAX, Vec3, key


@dataclass(frozen=True)
class WorldSpec:
    """How the real scene differs from the model (docs/design.md §11): what the model and physically based
    cameras of the camera-in-the-loop capture (:mod:`optlight.capture`), never what the planner
    assumes. Every default is the model itself (a Lambertian object, the exact light, no
    inter-reflection, a linear camera without noise)."""

    power_scale: float = key(
        1.0,
        "real light power over the model's light.power (0 would leave every capture unlit)",
        lo=0.0,
        lo_open=True,
    )
    ambient: float | None = key(None, "real ambient k_amb (default: the model's light.ambient)", lo=0.0)
    albedo_scale: float = key(
        1.0, "factor on the model's albedo (0 would make every capture black)", lo=0.0, lo_open=True
    )
    albedo_texture: float = key(
        0.0, "relative amplitude of a multiplicative albedo texture, 1 + t·sin·sin·sin of the position", lo=0.0, hi=1.0
    )
    texture_period_m: float = key(0.04, "period of the albedo texture", unit="m", lo=0.0, lo_open=True)
    bsdf: Literal["lambertian", "roughplastic", "principled"] = key(
        "lambertian", "reflectance of the real surface (the physically based camera; the model camera is Lambertian)"
    )
    roughness: float = key(0.3, "surface roughness (roughplastic α, principled roughness)", lo=0.0, hi=1.0, lo_open=True)
    specular: float = key(
        0.5, "specular strength (roughplastic specular reflectance, principled specular)", lo=0.0, hi=1.0
    )
    light_offset_m: Vec3 = key(
        (0.0, 0.0, 0.0),
        "where the real light is, relative to where the robot puts it, in the world frame (it does not turn "
        "with the flange: a misplaced model; a lamp mounted off its pose is lamp_offset_m); shorter than the "
        "light sphere's radius",
        unit="m",
    )
    lamp_offset_m: Vec3 = key(
        (0.0, 0.0, 0.0),
        "where the real lamp is on the flange: its offset from the nominal light frame ([robot] light_offset_m, "
        "light_rpy_deg), in that frame, so it turns with the arm as a real mount does; shorter than the light "
        "sphere's radius",
        unit="m",
    )
    lamp_rpy_deg: Vec3 = key(
        (0.0, 0.0, 0.0),
        "the real lamp's roll, pitch, yaw in the nominal light frame (roll and pitch tilt its axis, which the "
        "physically based camera's lambertian and spot profiles follow)",
        unit="deg",
    )
    light_radius_m: float = key(
        0.0, "radius of the real light's emitting area (0: a point; the physically based camera)", unit="m", lo=0.0
    )
    light_profile: Literal["isotropic", "lambertian", "spot"] = key(
        "isotropic",
        "angular emission: the same in every direction (point, sphere), cos of the angle to the light's axis "
        "(a disk facing the object), or a spot beam (point)",
    )
    spot_cutoff_deg: float = key(
        40.0, "half-angle where the spot beam ends (light_profile = spot)", unit="deg", lo=0.0, hi=90.0, lo_open=True
    )
    gamma: float = key(
        1.0,
        "camera response: recorded value s·(I/s)^(1/gamma) (beyond the range every capture is nearly "
        "black or white)",
        lo=GAMMA_RANGE[0],
        hi=GAMMA_RANGE[1],
    )
    noise_std: float = key(
        0.0, "sensor noise σ, pixel units, added before the response (at most light.saturation)", lo=0.0
    )
    seed: int = key(
        0, "seed of the sensor noise and of the physically based camera's samples", lo=0, hi=SEED_MAX
    )
    bounces: int = key(
        1, "light bounces the physically based camera traces (1: direct light only; more: inter-reflections)", lo=1, hi=32
    )
    spp: int = key(64, "samples per pixel of the physically based camera", lo=1, hi=65536)


@dataclass(frozen=True)
class LoopSpec:
    """The camera in the loop (docs/design.md §11): plan, capture at the landmarks, calibrate the model from
    the captures, re-plan on the calibrated model, until the measured objective stops improving."""

    iterations: int = key(4, "most plan-capture-calibrate rounds (the first is the open-loop plan)", lo=1, hi=50)
    tolerance: float = key(
        0.02, "relative decrease of the measured objective below which the loop stops", lo=0.0, hi=1.0
    )
    normals: Literal["model", "photometric_stereo"] = key(
        "model",
        "normals of the calibrated model: the mesh's, or photometric stereo's where 3 or more lights light a pixel",
    )
    saturation_level: float = key(
        0.98, "normalised camera value from which a pixel counts as saturated (left out of the fit)", lo=0.0, hi=1.0,
        lo_open=True,
    )
    dark_level: float = key(
        0.02, "normalised camera value below which a whole capture counts as black (its 99th percentile)", lo=0.0, hi=1.0
    )
    max_saturated_fraction: float = key(
        0.5, "a capture with more of its object pixels saturated is left out of the calibration", lo=0.0, hi=1.0,
        lo_open=True,
    )
    min_cosine: float = key(
        0.1, "smallest modelled shading v·max(0, n·l) of a lit pixel in the fit; dimmer lit pixels (shadow edges) are left out",
        lo=0.0, hi=1.0,
    )
    specular_mad: float = key(
        3.0, "pixels brighter than the fit by more than this many robust deviations (MAD) count as specular", lo=0.0,
        lo_open=True,
    )
    lamp: Literal["calibrate", "nominal"] = key(
        "calibrate",
        "estimate the lamp's pose on the flange (its offset and axis tilt in the light frame) from the captures "
        "and re-plan with it, or keep the nominal light frame",
    )
    servo_steps: int = key(8, "captures of the local photometric servo", lo=1, hi=1000)
    servo_step_deg: float = key(
        4.0, "first step of the photometric servo along the light sphere", unit="deg", lo=0.0, hi=45.0, lo_open=True
    )
