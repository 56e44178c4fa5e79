"""Calibration from captures (docs/design.md §11): what the model gets wrong, estimated from what the camera
recorded, and the calibrated model built from it.

The model of a recorded value, pixel p (model point x_p, normal n_p, albedo ρ_p) in capture k
(light at a_k, where the robot put it):

    Y_kp = s·(clip(c_p ρ_p (A S_kp + B), 0, s)/s)^(1/γ),     S_kp = v_kp · max(0, n_p·l_kp) · f_kp,

with S the model's shading (cast-shadow visibility v from shadow rays, falloff f of the light model),
A = g·E and B = g·k_amb (gain g, light power E, ambient k_amb), γ the camera response and c_p a
per-pixel albedo factor. Only products are observable: the gain stays the model's (a changed gain
shows as power and ambient changed in the same ratio), and a global albedo change shows in A and B
because the factors are normalised to a median of 1 over the calibrated pixels.

Robust fit:

1. a capture with more than ``max_saturated_fraction`` of its object pixels saturated
   (Y/s ≥ ``saturation_level``), or whose 99th percentile is below ``dark_level`` (black), is
   reported and left out;
2. an entry (k, p) is used when it is not saturated and its pixel is clearly lit,
   v·(n·l) ≥ ``min_cosine``, or clearly in attached shadow, n·l ≤ −``min_cosine`` (ambient only):
   cast-shadow pixels and shadow edges, where a small error of the light position changes the
   image most, are left out;
3. for a given γ the recorded values are linearised, L = s (Y/s)^γ, and (A, B, c) fitted by
   alternating least squares (c_p per pixel for fixed A, B; A, B for fixed c; renormalise);
   γ minimises the recorded-value residual Σ (Y − Ŷ)² over the used entries (bounded scalar search
   on log γ);
4. entries brighter than the fit by more than ``specular_mad`` robust deviations (1.4826 × the
   median absolute deviation of the linear residual, at least 0.1 % of s) are specular highlights:
   left out, and steps 3–4 repeated (three rounds);
5. steps 2–4 run with the shading of each light model (:data:`LIGHT_MODELS`: directional, f = 1,
   and point, f = (b/r)²), and the model whose fit leaves the smaller recorded-value residual on the
   entries both fits used is kept. A lamp at 0.4 m is a point light to the camera: the falloff across
   a 10 cm deep face is up to ~1.8×, which a directional model can only absorb into a wrong γ (a 5 cm
   disk lamp in the physically based camera calibrated to γ = 0.41 with the directional model).

6. (``[loop] lamp = "calibrate"``, every used capture's light rotation known) the lamp's pose on the
   flange (:mod:`optlight.capture.lamp`) is fitted on the chosen model's used entries, linearised
   with its γ; when some of it is identifiable, steps 2–5 run again with the lights where the
   calibrated lamp puts them, a' = a + R δ, and the lamp is fitted again from that fit
   (:data:`LAMP_ROUNDS` times in all): the shading's light positions and (A, B, c, γ) are
   estimated jointly by alternating between the two fits.

Normals: where three or more used lights light a pixel, photometric stereo
(:func:`optlight.photometric_stereo.recover_normals`, distant lights from O, strength A, the fitted
ambient image subtracted) on the linearised images; the calibrated model takes them where
``[loop] normals = "photometric_stereo"`` and keeps the mesh's otherwise (the deviation is reported).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
import pinocchio as pin
from numpy.typing import NDArray
from scipy.optimize import minimize_scalar

from optlight.capture import Array, Capture
from optlight.capture.lamp import LampCalibration, fit_lamp
from optlight.errors import OptlightError
from optlight.objectives import Objective
from optlight.photometric_stereo import recover_normals
from optlight.robot import Dynamics, load_robot
from optlight.scene import Scene
from optlight.scene.render import cosine_and_falloff
from optlight.scene.response import linearise, respond
from optlight.setup import Setup, lamp_of
from optlight.spec import LightSpec, LoopSpec, RobotSpec

#: Range of the response γ searched.
GAMMA_RANGE = (0.25, 4.0)
#: Rounds of fit and specular rejection; alternating least-squares sweeps per fit.
ROUNDS, SWEEPS = 3, 40
#: Smallest robust deviation of the specular test, as a fraction of the saturation value s.
MAD_FLOOR = 1e-3
#: The light models the calibration chooses between (module docstring, step 5).
LIGHT_MODELS: tuple[Literal["directional", "point"], ...] = ("directional", "point")
#: Most alternations between the photometric fit and the lamp's, and the change of the lamp's
#: positions (m) below which they stop (module docstring, step 6).
LAMP_ROUNDS, LAMP_TOLERANCE_M = 8, 2e-4


@dataclass(frozen=True, eq=False)
class Calibration:
    """The result of :func:`calibrate`.

    ``light_model`` the light model that fits the captures best and ``model_residual_rms`` each
    model's residual on the entries both used (step 5); ``power`` E and ``ambient`` k_amb (the
    model's gain kept), ``gamma`` γ; ``albedo_factor`` c (P,),
    1 where ``albedo_calibrated`` is False (a pixel without two used entries); ``normals`` (P, 3):
    photometric stereo's where ``normals_valid``, the mesh's elsewhere (None with fewer than 3 used
    captures); ``normal_deviation_deg``: median angle between them and the mesh's; ``used``: indices of
    the captures fitted; ``rejected``: index → why it was left out; ``entries``: how many (capture,
    pixel) entries were used, saturated, shadowed (edges and cast shadows) and specular; ``specular``
    (len(used), P): the entries left out as specular;
    ``residual_rms``: of Y − Ŷ over the used entries (renderer units); ``lamp``: the lamp's pose on
    the flange (step 6; None when not fitted: ``[loop] lamp = "nominal"`` or a capture without its
    light rotation), the fit's positions being where that lamp puts the lights."""

    light_model: Literal["directional", "point"]
    model_residual_rms: dict[str, float]
    power: float
    ambient: float
    gamma: float
    albedo_factor: Array
    albedo_calibrated: NDArray[np.bool_]
    normals: Array | None
    normals_valid: NDArray[np.bool_] | None
    normal_deviation_deg: float | None
    used: tuple[int, ...]
    rejected: dict[int, str]
    entries: dict[str, int]
    residual_rms: float
    specular: NDArray[np.bool_]
    lamp: LampCalibration | None = None

    def light(self, model: LightSpec) -> LightSpec:
        """The model's light with the calibrated light model, power and ambient."""
        return dataclasses.replace(model, model=self.light_model, power=self.power, ambient=self.ambient)

    def to_dict(self) -> dict[str, Any]:
        """The calibrated parameters and the fit's statistics, JSON-safe (no per-pixel arrays)."""
        c = self.albedo_factor[self.albedo_calibrated]
        return {
            "light_model": self.light_model,
            "model_residual_rms": dict(self.model_residual_rms),
            "power": self.power,
            "ambient": self.ambient,
            "gamma": self.gamma,
            "albedo_factor": {
                "calibrated_pixels": int(self.albedo_calibrated.sum()),
                "pixels": int(self.albedo_calibrated.size),
                "p5": float(np.percentile(c, 5)) if c.size else None,
                "median": float(np.median(c)) if c.size else None,
                "p95": float(np.percentile(c, 95)) if c.size else None,
            },
            "normals_recovered_pixels": None if self.normals_valid is None else int(self.normals_valid.sum()),
            "normal_deviation_deg": self.normal_deviation_deg,
            "used_captures": list(self.used),
            "rejected_captures": {str(k): v for k, v in self.rejected.items()},
            "entries": dict(self.entries),
            "residual_rms": self.residual_rms,
            "lamp": None if self.lamp is None else self.lamp.to_dict(),
        }


def capture_problem(pixels: Array, saturation: float, spec: LoopSpec) -> str | None:
    """Why a capture (its object pixels' recorded values (P,)) is left out, or None: saturated or black
    (module docstring, step 1)."""
    u = np.asarray(pixels, float) / saturation
    saturated = float(np.mean(u >= spec.saturation_level))
    if saturated > spec.max_saturated_fraction:
        return f"saturated ({100 * saturated:.0f}% of the object pixels at or above {spec.saturation_level:g} of full scale)"
    if np.percentile(u, 99) < spec.dark_level:
        return f"black (99% of the object pixels below {spec.dark_level:g} of full scale)"
    return None


def shading(scene: Scene, light_position: Array) -> tuple[Array, Array, Array]:
    """The model's S = v·max(0, n·l)·f, v·max(0, n·l) and n·l, each (P,), for a light at
    ``light_position``."""
    gb = scene.gbuffer
    cos, falloff = cosine_and_falloff(
        gb.points, gb.normals, light_position, scene.light.model, scene.sphere.center, scene.sphere.radius
    )
    lit = scene.visibility(light_position) * np.maximum(cos, 0.0)
    return lit * falloff, lit, cos


def calibrate(scene: Scene, captures: Sequence[Capture], spec: LoopSpec) -> Calibration:
    """Calibrate ``scene`` (the model at the camera's resolution) from ``captures`` (module docstring).

    Raises :class:`OptlightError` when fewer than two captures are usable."""
    gb, light = scene.gbuffer, scene.light
    s, g = light.saturation, light.gain
    recorded = np.array([c.image.ravel()[gb.pixel_index] for c in captures], float).reshape(len(captures), gb.size)
    rejected = {}
    for k, y in enumerate(recorded):
        reason = capture_problem(y, s, spec)
        if reason is not None:
            rejected[k] = reason
    used = tuple(k for k in range(len(captures)) if k not in rejected)
    if len(used) < 2:
        raise OptlightError(
            f"calibration needs at least 2 usable captures, got {len(used)} of {len(captures)}"
            + "".join(f"; capture {k}: {why}" for k, why in rejected.items())
        )
    y = recorded[list(used)]
    nominal = np.array([captures[k].light_position for k in used], float)
    rotations = [captures[k].light_rotation for k in used]
    model, chosen, residual = _photometric_fit(scene, y, nominal, spec)
    positions, lamp = nominal, None
    if spec.lamp == "calibrate" and all(r is not None for r in rotations):
        frames = np.array(rotations, float)
        for _ in range(LAMP_ROUNDS):
            fit = chosen.fit
            lamp = fit_lamp(
                chosen.scene, linearise(y, s, fit.gamma), chosen.weights, nominal, frames,
                fit.c * chosen.scene.gbuffer.albedo, fit.a, fit.b,
            )
            moved = lamp.positions(nominal, frames)
            if np.max(np.linalg.norm(moved - positions, axis=1), initial=0.0) <= LAMP_TOLERANCE_M:
                break
            positions = moved
            model, chosen, residual = _photometric_fit(scene, y, positions, spec)
    fit, weights = chosen.fit, chosen.weights
    normals, valid, deviation = _normals(chosen.scene, y, positions, fit, spec)
    return Calibration(
        light_model=model,
        model_residual_rms=residual,
        power=fit.a / g,
        ambient=max(fit.b, 0.0) / g,
        gamma=fit.gamma,
        albedo_factor=fit.c,
        albedo_calibrated=fit.calibrated,
        normals=normals,
        normals_valid=valid,
        normal_deviation_deg=deviation,
        used=used,
        rejected=rejected,
        entries={
            "used": int(weights.sum()),
            "saturated": int((~chosen.unsaturated).sum()),
            "shadowed": int((chosen.unsaturated & ~chosen.geometric).sum()),
            "specular": int(chosen.specular.sum()),
        },
        residual_rms=float(np.sqrt(fit.cost / max(int(weights.sum()), 1))),
        specular=chosen.specular,
        lamp=lamp,
    )


def _photometric_fit(
    scene: Scene, y: Array, positions: Array, spec: LoopSpec
) -> tuple[Literal["directional", "point"], _RobustFit, dict[str, float]]:
    """Steps 2–5 for lights at ``positions`` (K, 3): the light model kept, its fit, and each model's
    recorded-value residual on the entries both fits used."""
    s = scene.light.saturation
    fits = {m: _robust_fit(_with_light_model(scene, m), y, positions, spec) for m in LIGHT_MODELS}
    both = np.logical_and.reduce([f.weights for f in fits.values()])
    residual: dict[str, float] = {
        m: float(np.sqrt(np.mean((y - respond(f.fit.prediction, s, f.fit.gamma))[both] ** 2))) if both.any() else np.inf
        for m, f in fits.items()
    }
    model = min(LIGHT_MODELS, key=lambda m: (residual[m], m != scene.light.model))
    return model, fits[model], residual


def _with_light_model(scene: Scene, model: Literal["directional", "point"]) -> Scene:
    """``scene`` with its light's model set to ``model`` (itself when it already is)."""
    if scene.light.model == model:
        return scene
    return scene.calibrated(dataclasses.replace(scene.light, model=model), scene.gbuffer.albedo)


@dataclass(frozen=True)
class _RobustFit:
    """Steps 2–4 with one light model: the ``scene`` with that model, the last ``fit``, the entries
    not saturated, the ones clearly lit or clearly in attached shadow (``geometric``), the ones left
    out as ``specular`` and the ``weights`` (entries used)."""

    scene: Scene
    fit: _Fit
    unsaturated: NDArray[np.bool_]
    geometric: NDArray[np.bool_]
    specular: NDArray[np.bool_]

    @property
    def weights(self) -> NDArray[np.bool_]:
        return self.unsaturated & self.geometric & ~self.specular


def _robust_fit(scene: Scene, y: Array, positions: Array, spec: LoopSpec) -> _RobustFit:
    """Steps 2–4 of the module docstring for the recorded values ``y`` (K, P) of lights at
    ``positions`` (K, 3) with ``scene``'s light model."""
    light = scene.light
    s, g = light.saturation, light.gain
    shade, lit_cos, cos = (np.array(v) for v in zip(*(shading(scene, a) for a in positions), strict=True))
    unsaturated = y / s < spec.saturation_level
    geometric = (lit_cos >= spec.min_cosine) | (cos <= -spec.min_cosine)
    geometry = unsaturated & geometric
    specular = np.zeros_like(geometry)
    rho = scene.gbuffer.albedo
    fit: _Fit | None = None
    for _ in range(ROUNDS):
        used = _Entries.of(geometry & ~specular, shade)
        result = minimize_scalar(
            lambda t, used=used: _fit(y, used, rho, np.exp(t), s, g, light).cost,
            bounds=tuple(np.log(GAMMA_RANGE)),
            method="bounded",
            options={"xatol": 1e-5},
        )
        fit = _fit(y, used, rho, float(np.exp(result.x)), s, g, light)
        residual = linearise(y, s, fit.gamma) - fit.prediction
        r = residual[used.weights]
        sigma = max(1.4826 * float(np.median(np.abs(r - np.median(r)))), MAD_FLOOR * s)
        new = geometry & (residual > spec.specular_mad * sigma)
        if np.array_equal(new, specular):
            break
        specular = new
    assert fit is not None
    return _RobustFit(scene, fit, unsaturated, geometric, specular)


@dataclass(frozen=True)
class _Fit:
    a: float
    b: float
    c: Array
    calibrated: NDArray[np.bool_]
    gamma: float
    prediction: Array
    cost: float


@dataclass(frozen=True)
class _Entries:
    """The entries (k, p) a fit uses (``weights`` (K, P)), their shading ``shade`` (K, P) and what
    every γ's fit needs of them, summed over the captures per pixel once: W_p = Σ_k w_kp,
    S1_p = Σ_k w_kp S_kp, S2_p = Σ_k w_kp S_kp², and the pixels ``calibrated`` (used by two entries
    or more, one of them lit)."""

    weights: NDArray[np.bool_]
    shade: Array
    count: Array
    shade_sum: Array
    shade_square_sum: Array
    calibrated: NDArray[np.bool_]

    @classmethod
    def of(cls, weights: NDArray[np.bool_], shade: Array) -> _Entries:
        w = weights.astype(float)
        return cls(
            weights=weights,
            shade=shade,
            count=w.sum(axis=0),
            shade_sum=(w * shade).sum(axis=0),
            shade_square_sum=(w * shade * shade).sum(axis=0),
            calibrated=(weights.sum(axis=0) >= 2) & ((weights & (shade > 0)).sum(axis=0) >= 1),
        )


def _fit(y: Array, used: _Entries, rho: Array, gamma: float, s: float, g: float, light: LightSpec) -> _Fit:
    """Alternating least squares for A, B, c at a given γ (module docstring, step 3) on the ``used``
    entries of the recorded values ``y`` (K, P).

    With m_kp = ρ_p (A S_kp + B) and L the linearised values, each sweep solves
        c_p = Σ_k w L m / Σ_k w m² = ρ_p (A LS_p + B L1_p) / (ρ_p² (A² S2_p + 2AB S1_p + B² W_p)),
    then (A, B) from the 2 × 2 normal equations of Σ w (L − c ρ (A S + B))², whose entries are
    Σ_p (cρ)² (S2, S1, W) and Σ_p cρ (LS, L1): per-pixel sums over the captures (:class:`_Entries`;
    LS_p = Σ_k w L S, L1_p = Σ_k w L, once per γ), so a sweep costs O(P), not O(K·P). The same
    solution as summing every entry at every sweep (to ~1e-13: the sums are taken in another order),
    which on the default face (36 captures × 29,386 pixels, ~40 sweeps per fit, ~75 fits per round)
    would be nearly all of a loop round's time."""
    linear = linearise(y, s, gamma)
    w = used.weights.astype(float)
    wl = w * linear
    linear_sum, linear_shade_sum = wl.sum(axis=0), (wl * used.shade).sum(axis=0)
    count, s1, s2, calibrated = used.count, used.shade_sum, used.shade_square_sum, used.calibrated
    a, b = g * light.power, g * light.ambient
    c = np.ones(rho.size)
    for _ in range(SWEEPS):
        den = rho * rho * (a * a * s2 + 2.0 * a * b * s1 + b * b * count)
        num = rho * (a * linear_shade_sum + b * linear_sum)
        c = np.where(calibrated & (den > 0), num / np.where(den > 0, den, 1.0), 1.0)
        cr = c * rho
        cr2 = cr * cr
        off = float((cr2 * s1).sum())
        normal = np.array([[float((cr2 * s2).sum()), off], [off, float((cr2 * count).sum())]])
        rhs = np.array([(cr * linear_shade_sum).sum(), (cr * linear_sum).sum()])
        a_new, b_new = np.linalg.lstsq(normal, rhs, rcond=None)[0]
        scale = float(np.median(c[calibrated])) if calibrated.any() else 1.0
        c = np.where(calibrated, c / scale, 1.0)
        a_new, b_new = a_new * scale, b_new * scale
        done = abs(a_new - a) <= 1e-12 * max(abs(a), 1e-300) and abs(b_new - b) <= 1e-12 * max(abs(a), 1e-300)
        a, b = float(a_new), float(b_new)
        if done:
            break
    prediction = c * rho * (a * used.shade + b)
    cost = float((w * (y - respond(prediction, s, gamma)) ** 2).sum())
    return _Fit(a, b, c, calibrated, gamma, prediction, cost)


def _normals(
    scene: Scene, y: Array, positions: Array, fit: _Fit, spec: LoopSpec
) -> tuple[Array | None, NDArray[np.bool_] | None, float | None]:
    """Photometric stereo on the linearised captures (module docstring); (None, None, None) with
    fewer than 3 captures."""
    if len(positions) < 3:
        return None, None, None
    gb, s = scene.gbuffer, scene.light.saturation
    images = np.array([scene.to_image(p) for p in linearise(y, s, fit.gamma)])
    ambient = scene.to_image(fit.c * gb.albedo * max(fit.b, 0.0))
    directions = positions - scene.sphere.center
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    recovery = recover_normals(
        images,
        directions,
        np.full(len(positions), fit.a),
        mask=gb.mask,
        ambient=ambient,
        saturation=s,
        dark_level=spec.min_cosine * float(np.median(gb.albedo)) * fit.a / s,
        saturation_level=spec.saturation_level**fit.gamma,
    )
    valid = recovery.valid.ravel()[gb.pixel_index]
    recovered = recovery.normals.reshape(-1, 3)[gb.pixel_index]
    normals = np.where(valid[:, None], recovered, gb.normals)
    cos = np.clip(np.einsum("ij,ij->i", normals, gb.normals), -1.0, 1.0)
    deviation = float(np.median(np.degrees(np.arccos(cos[valid])))) if valid.any() else None
    return normals, valid, deviation


def lamp_robot(robot: RobotSpec, lamp: LampCalibration) -> RobotSpec:
    """``[robot]`` with its light frame moved to the calibrated lamp: flange · T(o, R_o) · T(δ) =
    flange · T(o + R_o δ, R_o), o = ``light_offset_m``, R_o from ``light_rpy_deg``."""
    r, p, y = np.deg2rad(robot.light_rpy_deg)
    rotation = np.asarray(pin.rpy.rpyToMatrix(r, p, y), float)
    offset = np.asarray(robot.light_offset_m, float) + rotation @ lamp.offset_m
    return dataclasses.replace(robot, light_offset_m=(float(offset[0]), float(offset[1]), float(offset[2])))


def calibrated_setup(setup: Setup, calibration: Calibration, normals: str = "model") -> Setup:
    """``setup`` with its scenes and objectives on the calibrated model: the calibrated light, the
    albedo ρ·c, the response γ, (``normals = "photometric_stereo"``) the recovered normals, and the
    robot's light frame on the calibrated lamp (:func:`lamp_robot`; the planner's IK then puts the
    estimated real lamp on the landmarks, the same joints, limits and start). The
    search scene takes each pixel's values from the camera pixel its point projects to (the model's
    where that pixel is not calibrated). The objectives keep their references and terms: the target
    stays what the problem says a good image is; only the model that predicts the images changes."""
    scene, search = setup.scene, setup.search_scene
    light = calibration.light(setup.problem.light)
    factor = calibration.albedo_factor
    use_normals = calibration.normals if normals == "photometric_stereo" else None
    cal_scene = scene.calibrated(light, scene.gbuffer.albedo * factor, use_normals, calibration.gamma)
    if search is scene:
        cal_search = cal_scene
    else:
        nearest = _nearest_camera_pixel(scene, search.gbuffer.points)
        found = nearest >= 0
        search_factor = np.where(found, factor[np.maximum(nearest, 0)], 1.0)
        search_normals = None
        if use_normals is not None:
            search_normals = np.where(found[:, None], use_normals[np.maximum(nearest, 0)], search.gbuffer.normals)
        cal_search = search.calibrated(light, search.gbuffer.albedo * search_factor, search_normals, calibration.gamma)

    def objective(base: Objective, on: Scene) -> Objective:
        return Objective(
            base.terms, base.reference, base.histogram, saturation=base.saturation, luminance=on.luminance(smooth=True)
        )

    cal_objective = objective(setup.objective, cal_scene)
    cal_search_objective = cal_objective if setup.search_objective is setup.objective else objective(
        setup.search_objective, cal_search
    )
    problem = dataclasses.replace(setup.problem, light=light)
    robot, dynamics = setup.robot, setup.dynamics
    lamp = calibration.lamp
    if lamp is not None and np.any(lamp.offset_m != 0.0):
        problem = dataclasses.replace(problem, robot=lamp_robot(problem.robot, lamp))
        robot = load_robot(problem)
        dynamics = Dynamics(robot, lamp_of(problem))
    return dataclasses.replace(
        setup,
        problem=problem,
        robot=robot,
        dynamics=dynamics,
        scene=cal_scene,
        search_scene=cal_search,
        objective=cal_objective,
        search_objective=cal_search_objective,
    )


def _nearest_camera_pixel(scene: Scene, points: Array) -> NDArray[np.intp]:
    """Index among ``scene``'s object pixels of the pixel each world point projects to (−1 where that
    pixel is not an object pixel)."""
    cam = scene.camera
    u, v, _ = cam.project(points)
    col = np.clip(np.round(u).astype(int), 0, cam.width - 1)
    row = np.clip(np.round(v).astype(int), 0, cam.height - 1)
    lookup = np.full(cam.width * cam.height, -1, np.intp)
    lookup[scene.gbuffer.pixel_index] = np.arange(scene.gbuffer.size)
    return lookup[row * cam.width + col]
