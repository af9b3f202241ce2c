"""Keyword options a user passes to a named component, checked before it is built.

Estimators, planners and mappers are built by name with keyword options
(``dgse estimate -p K=5``, ``get_estimator("kdmv", sigma=0.3)``).  A typo or a
value of the wrong type must give a clear :class:`~dgse.errors.InputDataError`
that names the option and what it takes, never a traceback from deep inside.

:func:`check_options` checks ``options`` against the signature and the type
hints of the callable (or class) that takes them: unknown names, and values
whose type does not fit a simple hint (``int``, ``float``, ``bool``, ``str``,
``Literal[...]``, ``X | None``, sequences of those).  Hints it does not know
(arrays, objects) are not checked.  A factory that forwards ``**kwargs`` to a
class states where they go with :func:`options_from`, so that the check reads
the class's signature.

Example::

    @options_from(AdjointEstimator, drop=("wind",))
    def make_adjoint(**kwargs): ...

    check_options("estimator 'adjoint'", make_adjoint, {"q_max": "abc"})
    # InputDataError: estimator 'adjoint': option q_max='abc' must be a number or None
"""

from __future__ import annotations

import inspect
import math
import os
import types
import typing
from collections.abc import Callable, Iterable, Mapping, Sequence
from typing import Any

from dgse.errors import InputDataError

__all__ = ["accepts", "check_options", "options_from"]

#: attribute set by :func:`options_from`
_ATTR = "__dgse_options__"
_NOT_CHECKED = object()


def options_from(
    target: Callable[..., Any], *, drop: Iterable[str] = (), extra: Mapping[str, Any] | None = None
) -> Callable[[Callable[..., Any]], Callable[..., Any]]:
    """Declare that a factory's ``**kwargs`` are ``target``'s keyword arguments.

    Args:
        target: the class or function that receives the options.
        drop: names of ``target`` the factory sets itself (not user options).
        extra: options the factory takes besides ``target``'s, name -> type hint.
    """

    def mark(fn: Callable[..., Any]) -> Callable[..., Any]:
        setattr(fn, _ATTR, (target, tuple(drop), dict(extra or {})))
        return fn

    return mark


def _hints(target: Callable[..., Any]) -> dict[str, Any]:
    for obj in (target.__init__, target) if inspect.isclass(target) else (target,):  # type: ignore[misc]
        try:
            return typing.get_type_hints(obj)
        except Exception:  # unresolvable string annotations: check names only
            continue
    return {}


def _accepted(target: Callable[..., Any]) -> tuple[dict[str, Any], bool]:
    """``({name: hint}, open)``: the keyword options ``target`` takes; ``open`` if it has ``**kwargs``."""
    drop: tuple[str, ...] = ()
    extra: dict[str, Any] = {}
    declared = getattr(target, _ATTR, None)
    if declared is not None:
        target, drop, extra = declared
    try:
        params = inspect.signature(target).parameters.values()
    except (TypeError, ValueError):  # no signature to read: accept anything
        return dict(extra), True
    hints = _hints(target)
    names: dict[str, Any] = {}
    is_open = False
    for p in params:
        if p.kind is p.VAR_KEYWORD:
            is_open = True
        elif p.kind in (p.POSITIONAL_OR_KEYWORD, p.KEYWORD_ONLY) and p.name not in drop:
            names[p.name] = hints.get(p.name, _NOT_CHECKED)
    names.update(extra)
    return names, is_open


def accepts(target: Callable[..., Any], name: str) -> bool:
    """True when ``target`` (a factory, class or function; see :func:`options_from`) takes option ``name``."""
    accepted, _ = _accepted(target)
    return name in accepted


def _describe(hint: Any) -> str:
    origin = typing.get_origin(hint)
    if hint is type(None):
        return "None"
    if origin is typing.Literal:
        return "one of " + ", ".join(repr(a) for a in typing.get_args(hint))
    if origin in (typing.Union, types.UnionType):
        return " or ".join(_describe(a) for a in typing.get_args(hint))
    if hint is bool:
        return "true or false"
    if hint is int:
        return "an integer"
    if hint is float:
        return "a number"
    if hint is str:
        return "a string"
    if origin in (list, tuple, Sequence) or hint in (list, tuple):
        return "a list"
    return getattr(hint, "__name__", str(hint))


def _convert(value: Any, hint: Any) -> Any:
    """``value`` fitted to ``hint`` (ints to floats); ``TypeError`` if it does not fit.

    Hints this function does not know are accepted as they are.
    """
    if hint is _NOT_CHECKED or hint is Any:
        return value
    origin = typing.get_origin(hint)
    if hint is type(None):
        if value is None:
            return None
        raise TypeError
    if origin is typing.Literal:
        if value in typing.get_args(hint):
            return value
        raise TypeError
    if origin in (typing.Union, types.UnionType):
        for arg in typing.get_args(hint):
            try:
                return _convert(value, arg)
            except TypeError:
                continue
        raise TypeError
    if hint is bool:
        if isinstance(value, bool):
            return value
        raise TypeError
    if hint is int:
        if isinstance(value, bool):
            raise TypeError
        if isinstance(value, int):
            return value
        if isinstance(value, float) and value.is_integer():
            return int(value)
        raise TypeError
    if hint is float:
        if isinstance(value, int | float) and not isinstance(value, bool):
            if math.isnan(value):
                raise TypeError
            return float(value)
        raise TypeError
    if hint is str:
        if isinstance(value, str):
            return value
        raise TypeError
    if hint in (os.PathLike,) or origin is os.PathLike:
        if isinstance(value, str | os.PathLike):
            return value
        raise TypeError
    if origin in (list, tuple, Sequence):
        if isinstance(value, str) or not isinstance(value, list | tuple):
            raise TypeError
        args = [a for a in typing.get_args(hint) if a is not Ellipsis]
        if len(args) == 1 or (origin is tuple and len(args) >= 1 and Ellipsis in typing.get_args(hint)):
            return type(value)(_convert(v, args[0]) for v in value)
        return value
    return value  # a hint we do not check (arrays, objects, paths)


def check_options(what: str, target: Callable[..., Any], options: Mapping[str, Any]) -> dict[str, Any]:
    """``options`` checked against what ``target`` takes; numbers converted to the hinted type.

    Args:
        what: how the message names the component, e.g. ``"estimator 'kdmv'"``.
        target: the factory, class or function the options are for (see :func:`options_from`).
        options: keyword options, e.g. parsed from ``-p KEY=VALUE``.

    Raises:
        InputDataError: an option ``target`` does not take (the message lists
            the ones it takes), or a value of the wrong type.
    """
    accepted, is_open = _accepted(target)
    unknown = sorted(set(options) - set(accepted))
    if unknown and not is_open:
        known = ", ".join(sorted(accepted)) or "none"
        raise InputDataError(f"unknown {what} option(s) {', '.join(unknown)}; known: {known}")
    out: dict[str, Any] = {}
    for name, value in options.items():
        hint = accepted.get(name, _NOT_CHECKED)
        try:
            out[name] = _convert(value, hint)
        except TypeError:
            raise InputDataError(f"{what}: option {name}={value!r} must be {_describe(hint)}") from None
    return out
