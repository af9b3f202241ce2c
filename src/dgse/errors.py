"""The exceptions DGSE raises on purpose.

Every error a user can cause (a bad file, an unknown engine, a sensor in a
wall) is a subclass of :class:`DGSEError`, so the command line can print its
message without a traceback.
"""

from __future__ import annotations


class DGSEError(Exception):
    """Base class of every error DGSE raises on purpose."""


class InputDataError(DGSEError, ValueError):
    """Input arrays, files or parameters that break the data contract."""


class CaseFileError(InputDataError):
    """A case file that cannot be read or fails validation."""


class UnsupportedError(DGSEError):
    """A valid request that this installation cannot serve (e.g. no OpenFOAM)."""


class ConvergenceError(DGSEError):
    """A solver that did not converge within its budget."""

    def __init__(self, message: str, info: dict | None = None) -> None:
        super().__init__(message)
        self.info = info or {}
