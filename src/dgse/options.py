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

Settings objects: a component with many options groups them into a few frozen
dataclasses derived from :class:`Settings` (each validates itself in
``__post_init__``), and takes one argument per group.  The one rule for users: a
dotted key sets one field of such an argument, ``fusion.floor=0.0`` (``-p
fusion.floor=0.0`` on the command line), on top of the argument's default (or of the
object given under the plain name); keys nest (``fusion.floor.map=0.1``), and a mapping
under the plain name means the same (``fusion={"floor": 0.0}``).  Unknown fields and
wrong types are errors as above, and the message lists the valid keys.  A
:class:`Settings` class with a ``from_value`` classmethod also takes a plain value
(:class:`dgse.belief.knowledge.PerLevel`: one value for every knowledge level).

The checks a ``__post_init__`` runs on one field are here too, so that a rule such as
"a switch is a bool, never a text" reads the same in every component:
:func:`check_switch`, :func:`check_whole`, :func:`check_number`, :func:`check_positive_numbers`.

Example::

    @options_from(AdjointEstimator, drop=("wind",))
    def make_adjoint(**kwargs): ...

    check_options("estimator 'adjoint'", make_adjoint, {"q_max": "abc"})
    # InputDataError: estimator 'adjoint': option q_max='abc' must be a number or None
    check_options("estimator 'dgse-phys'", make_dgse_phys, {"fusion.floor": 0.0})
    # {"fusion": NetworkFusion(..., floor=PerLevel(map=0.0, openings=0.0, wind=0.0))}
"""

from __future__ import annotations

import dataclasses
import inspect
import math
import os
import types
import typing
from collections.abc import Callable, Iterable, Mapping, Sequence
from typing import Any

from dgse.errors import InputDataError

__all__ = [
    "Settings",
    "accepts",
    "check_number",
    "check_options",
    "check_positive_numbers",
    "check_switch",
    "check_whole",
    "options_from",
]

#: attribute set by :func:`options_from`
_ATTR = "__dgse_options__"
_NOT_CHECKED = object()


def check_positive_numbers(key: str, values: Iterable[float], unit: str = "") -> tuple[float, ...]:
    """``values`` as a tuple of floats, all positive and finite; else an
    :class:`~dgse.errors.InputDataError` naming ``key`` (``unit`` follows "numbers" in it)."""
    try:
        out = tuple(float(v) for v in values)
    except (TypeError, ValueError):
        out = ()
    if not out or any(not (v > 0 and math.isfinite(v)) for v in out):
        raise InputDataError(f"{key} must be positive numbers{unit}, got {values!r}")
    return out


def check_number(
    key: str, value: float, *, low: float, high: float = math.inf, open_low: bool = False
) -> float:
    """``value`` as a float in ``[low, high]`` (``(low, high]`` with ``open_low``); else an
    :class:`~dgse.errors.InputDataError` naming ``key``."""
    v = float(value)
    ok = (v > low if open_low else v >= low) and v <= high
    if not ok or math.isnan(v):
        side = "(" if open_low else "["
        raise InputDataError(f"{key} must lie in {side}{low:g}, {high:g}], got {value!r}")
    return v


def check_whole(key: str, value: int, least: int) -> int:
    """``value`` (an int or a whole float, never a bool) as an int ``>= least``; else an
    :class:`~dgse.errors.InputDataError` naming ``key``."""
    if isinstance(value, bool) or not isinstance(value, int | float) or int(value) != value or value < least:
        raise InputDataError(f"{key} must be an integer >= {least}, got {value!r}")
    return int(value)


def check_switch(key: str, value: object) -> bool:
    """A true-or-false setting: a text such as ``"false"`` would read as true, so only a bool
    passes; else an :class:`~dgse.errors.InputDataError` naming ``key``."""
    if not isinstance(value, bool):
        raise InputDataError(f"{key} must be true or false, got {value!r}")
    return value


@dataclasses.dataclass(frozen=True)
class Settings:
    """Base of a settings object: a frozen dataclass of a component's options, each field with a
    documented default, checked in the subclass's ``__post_init__`` (raise
    :class:`~dgse.errors.InputDataError` naming the dotted key).  :func:`check_options` sets
    its fields from dotted keys; :meth:`to_dict` is what results files record of it."""

    def _set(self, name: str, value: Any) -> None:
        """Store a normalized value in ``__post_init__`` (the object is frozen)."""
        object.__setattr__(self, name, value)

    def to_dict(self) -> dict[str, Any]:
        """The fields as plain values (nested settings as dicts, tuples as lists)."""
        return {f.name: _plain(getattr(self, f.name)) for f in dataclasses.fields(self)}

    @classmethod
    def describe_option(cls, element: str) -> str:
        """How an option message names what a field of this type takes (``element``: the
        description of what ``from_value`` takes, where the class has one)."""
        return f"a {cls.__name__}"


def _plain(value: Any) -> Any:
    if isinstance(value, Settings):
        return value.to_dict()
    if isinstance(value, tuple | list):
        return [_plain(v) for v in value]
    return value


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


def _accepted(target: Callable[..., Any]) -> tuple[dict[str, Any], dict[str, Any], bool]:
    """``({name: hint}, {name: default}, open)``: the keyword options ``target`` takes, their
    defaults where they have one, and ``open`` if it has ``**kwargs``."""
    drop: tuple[str, ...] = ()
    extra: dict[str, Any] = {}
    declared = getattr(target, _ATTR, None)
    if declared is not None:
        target, drop, extra = declared
    try:
        params = inspect.signature(target).parameters.values()
    except (TypeError, ValueError):  # no signature to read: accept anything
        return dict(extra), {}, True
    hints = _hints(target)
    names: dict[str, Any] = {}
    defaults: dict[str, Any] = {}
    is_open = False
    for p in params:
        if p.kind is p.VAR_KEYWORD:
            is_open = True
        elif p.kind in (p.POSITIONAL_OR_KEYWORD, p.KEYWORD_ONLY) and p.name not in drop:
            names[p.name] = hints.get(p.name, _NOT_CHECKED)
            if p.default is not p.empty:
                defaults[p.name] = p.default
    names.update(extra)
    return names, defaults, is_open


def _settings_hint(hint: Any) -> Any:
    """The :class:`Settings` type in ``hint`` (itself, a parametrized one such as
    ``PerLevel[float]``, or one member of a union), else None."""
    origin = typing.get_origin(hint)
    if origin in (typing.Union, types.UnionType):
        for arg in typing.get_args(hint):
            found = _settings_hint(arg)
            if found is not None:
                return found
        return None
    cls = origin if origin is not None else hint
    return hint if isinstance(cls, type) and issubclass(cls, Settings) else None


def _settings_class(hint: Any) -> type[Settings]:
    origin = typing.get_origin(hint)
    return origin if origin is not None else hint


def _field_hints(hint: Any) -> dict[str, Any]:
    """``{field: hint}`` of the settings type ``hint``'s init fields, type variables replaced
    by ``hint``'s arguments (``PerLevel[float]``: every level's hint is ``float``)."""
    cls = _settings_class(hint)
    try:
        raw = typing.get_type_hints(cls)
    except Exception:  # unresolvable string annotations: check names only
        raw = {}
    subst = dict(zip(getattr(cls, "__parameters__", ()), typing.get_args(hint), strict=False))
    out: dict[str, Any] = {}
    for f in dataclasses.fields(cls):
        if f.init and not f.name.startswith("_"):
            h = raw.get(f.name, _NOT_CHECKED)
            out[f.name] = subst.get(h, _NOT_CHECKED) if isinstance(h, typing.TypeVar) else h
    return out


def _keys(prefix: str, hint: Any) -> list[str]:
    """The dotted keys of a settings type's fields (one level: a nested settings field is named
    once, its own fields are ``KEY.FIELD``)."""
    return [f"{prefix}.{name}" for name in _field_hints(hint)]


def _resolve(accepted: Mapping[str, Any], name: str) -> Any:
    """The hint of option ``name`` (dotted keys through the settings types), else ``KeyError``."""
    head, *rest = name.split(".")
    hint = accepted[head]
    for part in rest:
        st = _settings_hint(hint)
        if st is None:
            raise KeyError(name)
        hint = _field_hints(st)[part]
    return hint


def accepts(target: Callable[..., Any], name: str) -> bool:
    """True when ``target`` (a factory, class or function; see :func:`options_from`) takes option
    ``name`` (a dotted key: a field of one of its settings objects)."""
    accepted, _, _ = _accepted(target)
    try:
        _resolve(accepted, name)
    except KeyError:
        return False
    return True


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
    st = _settings_hint(hint)
    if st is not None:
        args = typing.get_args(st)
        return _settings_class(st).describe_option(_describe(args[0]) if args else "a value")
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
    st = _settings_hint(hint)
    if st is not None:
        cls = _settings_class(st)
        if isinstance(value, cls):
            return value
        make = getattr(cls, "from_value", None)
        if make is None:
            raise TypeError
        args = typing.get_args(st)
        return make(_convert(value, args[0]) if args else value)
    return value  # a hint we do not check (arrays, objects, paths)


def _checked(what: str, key: str, value: Any, hint: Any) -> Any:
    try:
        return _convert(value, hint)
    except TypeError:
        raise InputDataError(f"{what}: option {key}={value!r} must be {_describe(hint)}") from None


def _split(
    what: str, options: Mapping[str, Any], hints: Mapping[str, Any], prefix: str, is_open: bool
) -> tuple[dict[str, Any], dict[str, dict[str, Any]]]:
    """``(plain, nested)``: the options that set a name, and per settings-typed name the dotted
    keys below it (a mapping given to a settings-typed name counts as such keys).  Unknown
    names are errors (plain ones pass where ``is_open``)."""
    plain: dict[str, Any] = {}
    nested: dict[str, dict[str, Any]] = {}
    unknown: list[str] = []
    for key, value in options.items():
        head, dot, rest = str(key).partition(".")
        hint = hints.get(head)
        st = None if head not in hints else _settings_hint(hint)
        if head not in hints:
            if dot or not is_open:
                unknown.append(prefix + key)
            else:
                plain[head] = value
        elif dot:
            if st is None:
                unknown.append(prefix + key)
            else:
                nested.setdefault(head, {})[rest] = value
        elif st is not None and isinstance(value, Mapping):
            nested.setdefault(head, {}).update({str(k): v for k, v in value.items()})
        else:
            plain[head] = value
    if unknown:
        known: list[str] = []
        for name, hint in hints.items():  # at the top, a settings object's fields
            st = _settings_hint(hint) if not prefix else None
            known.extend(_keys(name, st) if st is not None else [prefix + name])
        listed = ", ".join(sorted(known)) or "none"
        raise InputDataError(f"unknown {what} option(s) {', '.join(sorted(unknown))}; known: {listed}")
    return plain, nested


def _with_fields(what: str, prefix: str, hint: Any, base: Any, changes: Mapping[str, Any]) -> Settings:
    """The settings object ``base`` (of type ``hint``) with ``changes`` (keys relative to ``prefix``)."""
    cls = _settings_class(hint)
    if not isinstance(base, cls):
        try:
            base = cls()
        except TypeError:
            key = prefix.rstrip(".")
            raise InputDataError(
                f"{what}: option {key} has no default to set fields of; give {key} itself"
            ) from None
    hints = _field_hints(hint)
    plain, nested = _split(what, changes, hints, prefix, is_open=False)
    new = {k: _checked(what, prefix + k, v, hints[k]) for k, v in plain.items()}
    for head, sub in nested.items():
        current = new.get(head, getattr(base, head))
        new[head] = _with_fields(what, f"{prefix}{head}.", _settings_hint(hints[head]), current, sub)
    return dataclasses.replace(base, **new)


def check_options(what: str, target: Callable[..., Any], options: Mapping[str, Any]) -> dict[str, Any]:
    """``options`` checked against what ``target`` takes; numbers converted to the hinted type,
    dotted keys made into the settings objects they set (see the module docstring).

    Args:
        what: how the message names the component, e.g. ``"estimator 'kdmv'"``.
        target: the factory, class or function the options are for (see :func:`options_from`).
        options: keyword options, e.g. parsed from ``-p KEY=VALUE``.

    Raises:
        InputDataError: an option ``target`` does not take (the message lists
            the ones it takes), a value of the wrong type, or a settings object's own check.
    """
    accepted, defaults, is_open = _accepted(target)
    plain, nested = _split(what, options, accepted, "", is_open)
    out = {k: _checked(what, k, v, accepted.get(k, _NOT_CHECKED)) for k, v in plain.items()}
    for head, sub in nested.items():
        base = out.get(head, defaults.get(head))
        out[head] = _with_fields(what, f"{head}.", _settings_hint(accepted[head]), base, sub)
    return out
