"""Errors raised by optlight.

Every failure a user can cause or meet is an :class:`OptlightError`; its message says what
failed, where, and what to change. The command line prints it in one line, without traceback.
"""

from __future__ import annotations


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
            detail += f", got {got!r}"
        super().__init__(f"{where}: {detail}")


class RobotError(OptlightError):
    """A robot or frame cannot be loaded (unknown name, missing file, unknown frame)."""


class UnreachableError(OptlightError):
    """A light pose (landmark or knot) cannot be reached by the robot."""


class SolverError(OptlightError):
    """A numerical solver failed in a way the caller cannot recover from."""


class VerificationError(OptlightError):
    """A plan failed independent verification; carries the report."""

    def __init__(self, message: str, report: object = None) -> None:
        self.report = report
        super().__init__(message)
