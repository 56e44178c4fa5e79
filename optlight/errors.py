"""Errors raised by optlight.

Every failure a user can cause or meet is an :class:`OptlightError`; its message says what
failed, where, and what to change. The command line prints it in one line, without traceback.
Values a user wrote are echoed as they wrote them (:func:`plain`): ``100000``, not ``100000.0`` or
``np.float64(100000.0)``.
"""

from __future__ import annotations

from typing import Any

#: IPOPT's return status when it stopped at its iteration limit (``[solver] max_iter``).
IPOPT_ITERATION_LIMIT = "Maximum_Iterations_Exceeded"


def plain(value: Any) -> str:
    """``repr`` of ``value`` with NumPy scalars and arrays turned into Python numbers and lists (so
    ``1.5``, not ``np.float64(1.5)``). Pass the value as the user wrote it: an int stays an int."""
    return repr(_plain(value))


def _plain(value: Any) -> Any:
    item = getattr(value, "item", None)
    if callable(item) and getattr(value, "shape", None) == ():
        return item()  # NumPy scalar or 0-d array
    tolist = getattr(value, "tolist", None)
    if callable(tolist) and hasattr(value, "shape"):
        return tolist()  # NumPy array
    if isinstance(value, list | tuple):
        return type(value)(_plain(v) for v in value)
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    return value


class OptlightError(Exception):
    """Base class of every error optlight raises on purpose."""


class ProblemError(OptlightError):
    """A problem file is invalid: names the file, the key path and what was expected."""

    def __init__(self, file: str, key: str, expected: str, got: object = None) -> None:
        self.file = file
        self.key = key
        self.expected = expected
        self.got = got
        where = f"{file}: {key}" if key else file
        detail = f"expected {expected}"
        if got is not None:
            detail += f", got {plain(got)}"
        super().__init__(f"{where}: {detail}")


class UsageError(OptlightError):
    """A command-line argument or an output location is refused: names the option and the value."""

    def __init__(self, option: str, message: str) -> None:
        self.option = option
        super().__init__(f"{option}: {message}")


class OutputError(OptlightError):
    """An output cannot be written: the disk is full, a file is too large, the folder is locked by
    another run. Names the folder and the cause."""


class RobotError(OptlightError):
    """A robot or frame cannot be loaded (unknown name, missing file, unknown frame)."""


class UnreachableError(OptlightError):
    """A light pose (landmark or knot) cannot be reached by the robot."""


class OutOfReachError(UnreachableError):
    """The robot reaches no light of the cap clear, or not a landmark it must capture, from where its
    base is: :func:`optlight.solve` adds where a base would (:mod:`optlight.relocation`)."""


class SolverError(OptlightError):
    """A numerical solver failed in a way the caller cannot recover from."""


class CaptureSolverError(SolverError):
    """The trajectory NLP found no way between the captures ``first`` and ``last`` (visiting order)."""

    def __init__(self, message: str, first: int, last: int) -> None:
        super().__init__(message)
        self.first, self.last = int(first), int(last)


def iteration_limit_error(what: str, max_iter: int) -> SolverError:
    """The error for an IPOPT solve of ``what`` that stopped at ``[solver] max_iter``: a solver
    limit the user can raise, not a property of the problem."""
    return SolverError(
        f"IPOPT stopped at max_iter = {max_iter} iterations in {what} before converging; "
        "raise [solver] max_iter"
    )


class VerificationError(OptlightError):
    """A plan failed independent verification; carries the report."""

    def __init__(self, message: str, report: object = None) -> None:
        self.report = report
        super().__init__(message)
