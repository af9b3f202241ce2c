"""The exceptions DGSE raises on purpose.

Every error a user can cause (a bad file, an unknown engine, a sensor in a
wall) is a subclass of :class:`DGSEError`, so the command line can print its
message without a traceback.

A message that tells the caller which argument to give names it as a field,
``{restart}``, and ``names`` says how a Python caller spells it
(``names={"restart": "restart=True"}``): ``str(error)`` reads
``"... start afresh with restart=True"``, and a front end with other
spellings (the command line's ``--restart``) asks for them with
:meth:`DGSEError.spelled`.
"""

from __future__ import annotations

import re
from collections.abc import Mapping

_FIELD = re.compile(r"\{([A-Za-z_][A-Za-z0-9_]*)\}")


def _fill(template: str, spellings: Mapping[str, str]) -> str:
    """``template`` with each ``{name}`` of ``spellings`` replaced (other braces left as they are)."""
    return _FIELD.sub(lambda m: spellings.get(m.group(1), m.group(0)), template)


class DGSEError(Exception):
    """Base class of every error DGSE raises on purpose.

    Args:
        *args: the message first, as for any exception.
        names: how Python callers spell the arguments the message names as ``{name}``.
    """

    def __init__(self, *args: object, names: Mapping[str, str] | None = None) -> None:
        self.names = dict(names or {})
        self.template = str(args[0]) if args and self.names else None
        if self.template is not None:
            args = (_fill(self.template, self.names), *args[1:])
        super().__init__(*args)

    def spelled(self, spellings: Mapping[str, str]) -> str:
        """The message with the arguments it names spelled as ``spellings`` says (others as in Python)."""
        if self.template is None:
            return str(self)
        known = {k: v for k, v in spellings.items() if k in self.names}
        return _fill(self.template, {**self.names, **known})


class InputDataError(DGSEError, ValueError):
    """Input arrays, files or parameters that break the data contract."""


class CaseFileError(InputDataError):
    """A case file that cannot be read or fails validation."""


class UnsupportedError(DGSEError):
    """A valid request that this installation cannot serve (e.g. no OpenFOAM)."""


class ConvergenceError(DGSEError):
    """A solver that did not converge within its budget."""

    def __init__(
        self, message: str, info: dict | None = None, *, names: Mapping[str, str] | None = None
    ) -> None:
        super().__init__(message, names=names)
        self.info = info or {}


class MassBalanceError(DGSEError):
    """A solver's gas field that breaks the conservation of the released gas (spec section 4:
    the scalar flux out of the outlets equals the release rate at steady state)."""
