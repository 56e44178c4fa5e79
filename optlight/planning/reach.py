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
clear ones near it (:class:`optlight.planning.placement.ClearPosture`: min |θ − θ_IK|² with the light
pinned at the cell, h(θ) = 0, c(θ) ≥ 0, v(θ) ≥ 0, joint limits; from θ_IK, then from the cell's IK
start), the placement policy's :class:`~optlight.planning.policy.Reacher`. A cell where neither
finds any is *taken by the environment*: the robot reaches the light there only by colliding or
blocking the camera (as far as these local solves can tell). The map then has three kinds of cells:
reachable (clear), taken by the environment, unreachable.

The polar plot is the cap as seen from the camera: azimuth 0 along x_S (image right), 90° along y_S
(image up), radius = zenith.
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.figure import Figure
from numpy.typing import NDArray

from optlight.planning.policy import Reacher
from optlight.robot import KinematicState, manipulability
from optlight.setup import Setup

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

    def figure(self) -> Figure:
        """Polar plot: manipulability per clear cell (colour), cells taken by the environment in
        grey with orange dots, unreachable cells as red crosses."""
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
        if taken.any() or len(zi):
            ax.legend(loc="lower left", bbox_to_anchor=(-0.15, -0.12))
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


def reachability_map(setup: Setup, zenith_step_deg: float = 5.0, azimuth_step_deg: float = 10.0) -> ReachabilityMap:
    """IK success and manipulability over the setup's light cap, and with its environment the cells
    the environment takes away (see the module docstring).

    Zenith from the sphere's ``zenith_min`` to ``zenith_max`` (both included) in steps of at most
    ``zenith_step_deg``; azimuth 0 … 360° (excluded) in steps of at most ``azimuth_step_deg``. Each
    cell is one :meth:`Reacher.attempt` (IK, then a clear posture), started from a reached neighbour.
    """
    robot, sphere = setup.robot, setup.sphere
    reacher = Reacher(setup)
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
    for i, zen in enumerate(zenith):
        for j, azi in enumerate(azimuth):
            if j > 0 and success[i, j - 1]:
                start = theta[i, j - 1]
            elif i > 0 and success[i - 1, j]:
                start = theta[i - 1, j]
            else:
                start = robot.theta_ref
            attempt = reacher.attempt(sphere.position(zen, azi), start)
            residual[i, j] = attempt.ik.residual
            if not attempt.ik.success:
                continue
            success[i, j] = True
            theta[i, j] = attempt.ik.theta if attempt.theta is None else attempt.theta
            if setup.environment is not None:
                clearance[i, j] = attempt.clearance
                taken[i, j] = attempt.theta is None
            manip[i, j] = manipulability(KinematicState.compute(robot, theta[i, j]).jacobian)
    return ReachabilityMap(
        robot.name,
        zenith,
        azimuth,
        success,
        manip,
        theta,
        residual,
        time.perf_counter() - t0,
        environment=setup.environment is not None,
        taken=taken,
        clearance=clearance,
    )
