"""The verification's result: the tolerances, the violations and per-check results, the torque summary
and :class:`VerificationReport`, which decides and tells whether a plan passed."""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

from optlight.errors import VerificationError
from optlight.jsondata import json_safe

#: Episodes kept per check in :attr:`VerificationReport.violations`.
MAX_EPISODES = 5


@dataclass(frozen=True)
class Tolerances:
    """What counts as a violation. Units: relative (limit_rel), rad, m."""

    limit_rel: float = 1e-3
    position_rad: float = 1e-6
    h_m: float = 1e-6
    aim_rad: float = 1e-4
    landmark_m: float = 1e-6
    path_m: float = 5e-3
    interpolation_rad: float = 1e-4


@dataclass(frozen=True)
class Violation:
    """The worst sample of one episode. ``value`` and ``limit`` are physical: the joint position and
    the bound it crossed (rad), |q̇| and v_max(1 + limit_rel) (rad/s), |q̈| and its limit (rad/s²),
    |h|, the landmark or path distance (m), the aiming angle (rad)."""

    check: str
    time_s: float
    joint: str | None
    value: float
    limit: float
    message: str


@dataclass(frozen=True)
class CheckResult:
    """Worst value of one check over all its samples, in the check's measure: the largest excess
    over the position limits (rad; negative = smallest margin), the largest |q̇_j|/v_max,j or
    |q̈_j|/a_max,j (ratio), the largest |h|, landmark or path distance (m), aiming angle (rad)."""

    name: str
    measure: str
    unit: str
    max_value: float
    limit: float
    time_s: float | None
    joint: str | None
    failing_samples: int
    episodes: int
    samples: int

    @property
    def passed(self) -> bool:
        """No failing sample."""
        return self.failing_samples == 0


@dataclass(frozen=True)
class TorqueSummary:
    """The joint torques along the plan: per joint (``joints``) the peak |τ_j| (``peak_nm``, N·m) and
    when (``time_s``), the limit (``limit_nm``) and the peak's fraction of it (``fraction``), None
    for a robot without published limits; ``source`` where the limits come from."""

    joints: tuple[str, ...]
    peak_nm: tuple[float, ...]
    time_s: tuple[float, ...]
    limit_nm: tuple[float, ...] | None
    fraction: tuple[float, ...] | None
    source: str

    def lines(self) -> list[str]:
        """One line per joint: peak, limit and fraction (or that no limit is published)."""
        if self.limit_nm is None or self.fraction is None:
            head = [f"Joint torques (not checked: {self.source}):"]
            return head + [
                f"  {j}: peak |τ| = {p:.3g} N·m at t = {t:.4f} s"
                for j, p, t in zip(self.joints, self.peak_nm, self.time_s, strict=True)
            ]
        rows = zip(self.joints, self.peak_nm, self.time_s, self.limit_nm, self.fraction, strict=True)
        return [f"Joint torques (limits: {self.source}):"] + [
            f"  {j}: peak |τ| = {p:.3g} N·m at t = {t:.4f} s, {f:.1%} of {lim:.4g} N·m" for j, p, t, lim, f in rows
        ]


@dataclass(frozen=True)
class VerificationReport:
    """Outcome of :func:`verify_trajectory`."""

    checks: dict[str, CheckResult]
    violations: tuple[Violation, ...]
    duration_s: float
    samples: int
    rate_hz: float
    tolerances: Tolerances
    skipped: tuple[str, ...] = ()
    elapsed_s: float = 0.0
    advisory: tuple[str, ...] = ()
    torques: TorqueSummary | None = None

    @property
    def passed(self) -> bool:
        """Every check passed, the advisory ones aside."""
        return all(c.passed for name, c in self.checks.items() if name not in self.advisory)

    @property
    def counts(self) -> dict[str, int]:
        """Number of failing samples per check."""
        return {k: c.failing_samples for k, c in self.checks.items()}

    @property
    def maxima(self) -> dict[str, float]:
        """Worst value per check, in the check's measure (see :class:`CheckResult`)."""
        return {k: c.max_value for k, c in self.checks.items()}

    def to_dict(self) -> dict[str, Any]:
        """Plain JSON-safe data (non-finite numbers become None)."""
        return {
            "passed": self.passed,
            "duration_s": self.duration_s,
            "samples": self.samples,
            "rate_hz": self.rate_hz,
            "elapsed_s": self.elapsed_s,
            "tolerances": asdict(self.tolerances),
            "skipped": list(self.skipped),
            "advisory": list(self.advisory),
            "counts": self.counts,
            "checks": {k: {**json_safe(c), "passed": c.passed} for k, c in self.checks.items()},
            "violations": json_safe(self.violations),
            "torques": json_safe(self.torques) if self.torques is not None else None,
        }

    def summary(self) -> str:
        """A readable multi-line account: verdict, one line per check, the recorded violations."""
        verdict = "PASSED" if self.passed else "FAILED"
        lines = [
            f"Verification {verdict}: {self.duration_s:.3f} s trajectory, {self.samples} samples "
            f"(≥ {self.rate_hz:g} Hz), checked in {self.elapsed_s:.2f} s",
        ]
        width = max(len(k) for k in self.checks) if self.checks else 8
        for name, c in self.checks.items():
            where = ""
            if c.time_s is not None:
                where = f" at t = {c.time_s:.4f} s" + (f" ({c.joint})" if c.joint else "")
            unit = f" {c.unit}" if c.unit else ""
            mark = "ok  " if c.passed else ("warn" if name in self.advisory else "FAIL")
            lines.append(
                f"  {mark} {name:<{width}}  {c.measure} = {c.max_value:.6g}{unit}{where}; "
                f"limit {c.limit:.6g}{unit}; {c.failing_samples}/{c.samples} samples over in {c.episodes} episodes"
            )
        for name in self.skipped:
            lines.append(f"  skip {name:<{width}}  not checked")
        for name in self.advisory:
            if name in self.checks:
                lines.append(f"  note {name:<{width}}  reported only: it does not decide the verdict")
        if self.torques is not None:
            lines.extend(self.torques.lines())
        if self.violations:
            lines.append(f"Violations (first {MAX_EPISODES} episodes per check):")
            lines.extend(f"  {v.check}: {v.message}" for v in self.violations)
        return "\n".join(lines)


def ensure_verified(report: VerificationReport) -> None:
    """Raise :class:`VerificationError` (carrying the report) unless the report passed."""
    if not report.passed:
        raise VerificationError(report.summary(), report)

