"""Reachability map of the light cap: where on the sphere the robot can put the light.

Over a zenith × azimuth grid of the allowed cap (zenith_min … zenith_max, all azimuths), the 5-D
generalized IK (position + optical axis through O) is solved for the problem's robot and base
placement, warm-started from the neighbouring cell (previous azimuth of the same zenith ring, else
the same azimuth one ring in), and the manipulability w = sqrt(det(J Jᵀ)) of the light Jacobian is
recorded where it succeeds.

The environment. With ``[environment] enabled`` a reached cell is also checked against the NLPs'
model of the environment (:meth:`optlight.environment.Environment.sphere_clearance`: robot spheres to
the obstacles and to each other, minus the margins, and to the camera's view cone, the light being a
capture): every row must be ≥ 0. The IK does not see the environment, and a redundant arm has other
joint angles for the same light, so where the IK's configuration breaks a row a small NLP looks for
clear ones near it (:class:`optlight.planning.placement.ClearPosture`: min |θ − θ₀|² with the light
pinned at the cell, h(θ) = 0, c(θ) ≥ 0, v(θ) ≥ 0, joint limits; θ₀ the cell's IK start, solved from
θ_IK; after the IK's random restarts, from θ₀, then with θ₀ = θ_IK), the placement policy's
:class:`~optlight.planning.policy.Reacher`. The chain gives each
cell one start, and the posture it carries may be on an IK branch that blocks the camera where
another branch is clear; so a cell left blocked is tried again from the posture of each clear
neighbour, until no more cells become clear. A cell where none of these finds clear joint angles is
*taken by the environment*: the robot reaches the light there only by colliding or blocking the
camera (as far as these local solves can tell). The map then has three kinds of cells: reachable
(clear), taken by the environment, unreachable. :class:`ClearField` smooths the clear cells into a
function a light set's NLP keeps its lights on.

The polar plot is the cap as seen from the camera: azimuth 0 along x_S (image right), 90° along y_S
(image up), radius = zenith.
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import casadi as ca
import numpy as np
from numpy.typing import ArrayLike, NDArray

from optlight.geometry import direction_in_sphere_frame
from optlight.planning.lightsets import angles_of
from optlight.planning.policy import Reacher
from optlight.robot import KinematicState, manipulability

if TYPE_CHECKING:  # imported where the figure is made: see optlight.viz.layout
    from matplotlib.figure import Figure

Array = NDArray[np.float64]


@dataclass(frozen=True)
class ReachabilityMap:
    """IK over the light cap. Arrays are indexed [zenith, azimuth]; angles in rad.

    ``success`` (Z, A) bool: the IK reached the cell; ``manipulability`` (Z, A), NaN where the IK
    failed; ``theta`` (Z, A, n) joint angles (NaN where it failed): the clear ones when the IK's were
    not; ``residual`` (Z, A) final |e| in m; ``time_s`` total time (IK and clearance).

    ``environment``: whether the environment was checked. ``taken`` (Z, A) bool: reached, but taken
    by the environment (no clear joint angles found); ``clearance`` (Z, A) the smallest environment
    row at ``theta`` (m; negative where taken, NaN where the IK failed). Without the environment
    ``taken`` is all False and ``clearance`` all NaN.
    """

    robot: str
    zenith: Array
    azimuth: Array
    success: NDArray[np.bool_]
    manipulability: Array
    theta: Array
    residual: Array
    time_s: float
    environment: bool
    taken: NDArray[np.bool_]
    clearance: Array

    @property
    def clear(self) -> NDArray[np.bool_]:
        """(Z, A) cells reached and clear of the environment (all reached cells without one)."""
        return self.success & ~self.taken

    @property
    def directions(self) -> Array:
        """(Z·A, 3) unit directions of the cells (sphere frame), row-major like ``clear.ravel()``."""
        zenith, azimuth = np.meshgrid(self.zenith, self.azimuth, indexing="ij")
        return direction_in_sphere_frame(zenith, azimuth).reshape(-1, 3)

    @property
    def reachable_fraction(self) -> float:
        """Fraction of the grid cells the IK reached (whether or not the environment takes them)."""
        return float(self.success.mean())

    @property
    def clear_fraction(self) -> float:
        """Fraction of the grid cells reached clear of the environment."""
        return float(self.clear.mean())

    @property
    def taken_fraction(self) -> float:
        """Fraction of the grid cells taken by the environment (reached, but never clear of it)."""
        return float(self.taken.mean())

    @property
    def taken_cells(self) -> list[tuple[float, float]]:
        """(zenith, azimuth) in degrees of every cell taken by the environment."""
        zi, ai = np.nonzero(self.taken)
        return [
            (float(np.rad2deg(self.zenith[i])), float(np.rad2deg(self.azimuth[j])))
            for i, j in zip(zi, ai, strict=True)
        ]

    @property
    def unreachable(self) -> list[tuple[float, float]]:
        """(zenith, azimuth) in degrees of every cell the IK did not reach."""
        zi, ai = np.nonzero(~self.success)
        return [
            (float(np.rad2deg(self.zenith[i])), float(np.rad2deg(self.azimuth[j])))
            for i, j in zip(zi, ai, strict=True)
        ]

    @property
    def status(self) -> NDArray[np.str_]:
        """(Z, A) "reachable" (and clear), "taken" (by the environment) or "unreachable" per cell."""
        out = np.full(self.success.shape, "unreachable", dtype="<U11")
        out[self.success] = "reachable"
        out[self.taken] = "taken"
        return out

    def to_dict(self) -> dict[str, Any]:
        """Plain data for ``reachability.json`` (degrees; null where the IK failed). ``status`` per
        cell: "reachable", "taken" (by the environment) or "unreachable"; ``success`` is the IK's."""

        def nulls(a: Array) -> list[Any]:
            return [[None if not np.isfinite(x).all() else np.round(x, 6).tolist() for x in row] for row in a]

        return {
            "robot": self.robot,
            "zenith_deg": np.rad2deg(self.zenith).round(6).tolist(),
            "azimuth_deg": np.rad2deg(self.azimuth).round(6).tolist(),
            "environment": self.environment,
            "reachable_fraction": self.reachable_fraction,
            "clear_fraction": self.clear_fraction,
            "taken_fraction": self.taken_fraction,
            "success": self.success.tolist(),
            "status": self.status.tolist(),
            "clearance_m": nulls(self.clearance),
            "manipulability": nulls(self.manipulability),
            "residual_m": self.residual.tolist(),
            "theta_rad": nulls(self.theta),
            "time_s": self.time_s,
        }

    def figure(self, lights: ArrayLike | None = None) -> Figure:
        """Polar plot: manipulability per clear cell (colour), cells taken by the environment in
        grey with orange dots, unreachable cells as red crosses; ``lights`` (N, 3) unit directions
        (sphere frame) as white stars when given (a light set designed over the map)."""
        from matplotlib.figure import Figure

        fig = Figure(figsize=(6.0, 5.2), layout="constrained")
        ax = fig.add_subplot(projection="polar")
        z_deg = np.rad2deg(self.zenith)
        dz = z_deg[1] - z_deg[0] if len(z_deg) > 1 else 1.0
        da = self.azimuth[1] - self.azimuth[0] if len(self.azimuth) > 1 else 2 * np.pi
        r_edges = np.clip(np.append(z_deg - dz / 2, z_deg[-1] + dz / 2), 0.0, None)
        a_edges = np.append(self.azimuth - da / 2, self.azimuth[-1] + da / 2)
        mesh = ax.pcolormesh(
            a_edges,
            r_edges,
            np.ma.masked_where(~self.clear, self.manipulability),
            cmap="viridis",
            shading="flat",
        )
        fig.colorbar(mesh, ax=ax, label="manipulability  sqrt(det J Jᵀ)", shrink=0.8)
        taken = self.taken
        if taken.any():
            ax.pcolormesh(
                a_edges,
                r_edges,
                np.ma.masked_where(~taken, np.ones(taken.shape)),
                cmap="Greys",
                vmin=0.0,
                vmax=2.0,
                shading="flat",
            )
            zi, ai = np.nonzero(taken)
            ax.plot(
                self.azimuth[ai], z_deg[zi], "o", color="tab:orange", ms=4, label="taken by the environment"
            )
        zi, ai = np.nonzero(~self.success)
        if len(zi):
            ax.plot(self.azimuth[ai], z_deg[zi], "x", color="red", ms=6, label="unreachable")
        if lights is not None:
            zenith, azimuth = angles_of(lights)
            ax.plot(azimuth, np.rad2deg(zenith), "*", color="white", mec="black", ms=11, label="lights")
        if taken.any() or len(zi) or lights is not None:  # below the plot: inside it, it covered the 270° label
            fig.legend(loc="outside lower center", ncols=3, frameon=False)
        ax.set_ylim(0.0, r_edges[-1])  # radial limits
        title = f"{self.robot}: light cap reachable in {100 * self.reachable_fraction:.1f} % of cells"
        if self.environment:
            title += f",\nclear of the environment in {100 * self.clear_fraction:.1f} %"
        ax.set_title(f"{title}\n(seen from the camera; radius = zenith in degrees)", fontsize=10)
        return fig

    def save(self, folder: str | Path) -> tuple[Path, Path]:
        """Write ``reachability.png`` and ``reachability.json`` into ``folder``; return their paths."""
        out = Path(folder)
        out.mkdir(parents=True, exist_ok=True)
        png, js = out / "reachability.png", out / "reachability.json"
        self.figure().savefig(png, dpi=120)
        js.write_text(json.dumps(self.to_dict(), indent=1))
        return png, js


@dataclass(frozen=True)
class ClearField:
    """A smooth indicator of where on the cap the robot reaches the light clear, from a map's cells.

    f(d) = Σ_k s_k w_k(d) / Σ_k w_k(d),  w_k(d) = exp(κ (d·c_k − 1)) ≈ exp(−γ_k² / (2σ²)),

    with ``centers`` c_k (M, 3) the cells' unit directions (sphere frame), ``signs`` s_k = +1 for a
    clear cell and −1 for one taken by the environment or unreachable, γ_k the angle from d to c_k
    and κ = 1/σ² (``kappa``, rad⁻²): a Gaussian-weighted vote of the nearby cells, in [−1, 1],
    positive where clear cells are nearer, 0 half-way between a clear and a blocked cell. f has a
    NumPy and a CasADi form (the light-set NLP's ``allowed`` rows).
    """

    centers: Array
    signs: Array
    kappa: float

    @classmethod
    def from_map(cls, reach: ReachabilityMap, width: float | None = None) -> ClearField:
        """The field of ``reach``'s cells; ``width`` σ (rad) defaults to half the map's zenith step,
        so that each point is decided by its nearest cells."""
        if width is None:
            width = 0.5 * float(np.diff(reach.zenith).min()) if len(reach.zenith) > 1 else 0.05
        return cls(reach.directions, np.where(reach.clear, 1.0, -1.0).ravel(), 1.0 / width**2)

    def numpy(self, directions: ArrayLike) -> Array:
        """f at unit directions (..., 3), sphere frame."""
        w = np.exp(self.kappa * (np.asarray(directions, float) @ self.centers.T - 1.0))
        return (w @ self.signs) / w.sum(axis=-1)

    def casadi(self, directions: ca.MX) -> ca.MX:
        """f at the rows of the N×3 MX ``directions`` (N×1)."""
        w = ca.exp(self.kappa * (ca.mtimes(directions, ca.DM(self.centers.T)) - 1.0))
        return ca.mtimes(w, ca.DM(self.signs)) / ca.sum2(w)


def reachability_map(
    reacher: Reacher,
    zenith_step_deg: float = 5.0,
    azimuth_step_deg: float = 10.0,
    *,
    progress: Callable[[int, int], None] | None = None,
) -> ReachabilityMap:
    """IK success and manipulability over the light cap of the reacher's work cell, and with its
    environment the cells the environment takes away (see the module docstring).

    Zenith from the sphere's ``zenith_min`` to ``zenith_max`` (both included) in steps of at most
    ``zenith_step_deg``; azimuth 0 … 360° (excluded) in steps of at most ``azimuth_step_deg``. Each
    cell is one :meth:`Reacher.attempt` (IK, then a clear posture), started from a reached neighbour;
    then a cell left blocked is tried again from each clear neighbour's angles, until no more become
    clear. ``progress(done, total)`` per cell.
    """
    cell = reacher.cell
    robot, sphere = cell.robot, cell.sphere
    zmin, zmax = np.rad2deg(sphere.zenith_min), np.rad2deg(sphere.zenith_max)
    n_z = int(np.ceil((zmax - zmin) / zenith_step_deg - 1e-9)) + 1
    n_a = int(np.ceil(360.0 / azimuth_step_deg - 1e-9))
    zenith = np.deg2rad(np.linspace(zmin, zmax, n_z))
    azimuth = np.deg2rad(np.arange(n_a) * 360.0 / n_a)

    success = np.zeros((n_z, n_a), bool)
    manip = np.full((n_z, n_a), np.nan)
    theta = np.full((n_z, n_a, robot.n), np.nan)
    residual = np.full((n_z, n_a), np.nan)
    taken = np.zeros((n_z, n_a), bool)
    clearance = np.full((n_z, n_a), np.nan)
    t0 = time.perf_counter()

    def record(i: int, j: int, start: Array) -> None:
        """Try cell (i, j) from ``start``; keep the attempt unless the cell already has a better one
        (clear before taken before unreached; the smaller residual among unreached)."""
        attempt = reacher.attempt(sphere.position(zenith[i], azimuth[j]), start)
        if not attempt.ik.success:
            if not success[i, j]:
                residual[i, j] = np.fmin(residual[i, j], attempt.ik.residual)
            return
        if success[i, j] and (attempt.theta is None or not taken[i, j]):
            return
        residual[i, j] = attempt.ik.residual
        success[i, j] = True
        theta[i, j] = attempt.ik.theta if attempt.theta is None else attempt.theta
        if cell.environment is not None:
            clearance[i, j] = attempt.clearance
            taken[i, j] = attempt.theta is None
        manip[i, j] = manipulability(KinematicState.compute(robot, theta[i, j]).jacobian)

    for i in range(n_z):
        for j in range(n_a):
            if j > 0 and success[i, j - 1]:
                record(i, j, theta[i, j - 1])
            elif i > 0 and success[i - 1, j]:
                record(i, j, theta[i - 1, j])
            else:
                record(i, j, robot.theta_ref)
            if progress is not None:
                progress(i * n_a + j + 1, n_z * n_a)
    # The chain gives each cell one start; a cell it left blocked may be clear from another neighbour's
    # posture (another IK branch, as the placement's chain of lights may bring): grow the clear region
    # until no blocked cell next to a clear one becomes clear from that one's angles.
    tried: set[tuple[int, int, int, int]] = set()
    grown = True
    while grown:
        grown = False
        clear = success & ~taken
        for i, j in zip(*np.nonzero(~clear), strict=True):
            for ni, nj in ((i, (j - 1) % n_a), (i, (j + 1) % n_a), (i - 1, j), (i + 1, j)):
                if 0 <= ni < n_z and clear[ni, nj] and (i, j, ni, nj) not in tried:
                    tried.add((i, j, ni, nj))
                    record(i, j, theta[ni, nj])
                    if success[i, j] and not taken[i, j]:
                        grown = True
                        break
    return ReachabilityMap(
        robot.name,
        zenith,
        azimuth,
        success,
        manip,
        theta,
        residual,
        time.perf_counter() - t0,
        environment=cell.environment is not None,
        taken=taken,
        clearance=clearance,
    )
