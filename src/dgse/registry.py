"""One registry mechanism for everything DGSE looks up by name: estimators, planners, engines, suites.

A :class:`Registry` maps a name to an :class:`Entry`: a factory (a callable, or a
lazy ``"module:attr"`` string imported on first use, so that listing names imports
nothing heavy) and what the rest of the toolkit shows of it (a label, a colour and
a marker for figures, a one-line description).  Third-party packages add entries
through package entry points, one per name, in the registry's group
(``dgse.estimators``, ``dgse.planners``, ``dgse.engines``)::

    [project.entry-points."dgse.estimators"]
    my-method = "my_package.module:make_my_method"

The entry point's object is either the factory itself or an :class:`Entry` (to
give a label and colour too).  Entry points are read once, on first use; a
built-in name cannot be taken by a plugin.
"""

from __future__ import annotations

import importlib
import re
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field, replace
from typing import Any, Generic, TypeVar

from dgse.errors import InputDataError, UnsupportedError

__all__ = ["Entry", "Registry", "lazy_attributes"]

T = TypeVar("T")

_NAME = re.compile(r"^[a-z0-9][a-z0-9_.+-]*$")


@dataclass(frozen=True)
class Entry:
    """One registered name.

    Attributes:
        name: lower case (``[a-z0-9][a-z0-9_.+-]*``).
        target: the factory, or ``"module:attr"`` naming it (imported on first use).
        label: how figures and tables name it (the name when None).
        color: its colour in figures (matplotlib's cycle when None).
        marker: its matplotlib marker in figures.
        description: one line for listings.
        tags: what families it belongs to (``"gdm"``: a gas distribution mapping method, ...).
        extra: whatever one kind of entry needs besides (a suite's title, ...).
    """

    name: str
    target: Callable[..., Any] | str
    label: str | None = None
    color: str | None = None
    marker: str = "x"
    description: str = ""
    tags: tuple[str, ...] = ()
    extra: dict[str, Any] = field(default_factory=dict, compare=False)

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not _NAME.match(self.name):
            raise InputDataError(f"invalid name {self.name!r} (lower case letters, digits, _ . + -)")
        if isinstance(self.target, str):
            if ":" not in self.target:
                raise InputDataError(f"a lazy factory must be 'module:attr', got {self.target!r}")
        elif not callable(self.target):
            raise InputDataError(f"the factory of {self.name!r} is not callable")

    @property
    def display(self) -> str:
        """The label, or the name when there is none."""
        return self.label or self.name


class Registry(Generic[T]):
    """Names -> :class:`Entry` for one kind of thing (``"estimator"``, ``"planner"``, ...).

    Args:
        kind: what is registered, for messages.
        entries: the built-in entries.
        group: the package entry-point group that plugins register in (None: no plugins).
        ordered: list names in the order registered (default: sorted).
    """

    def __init__(
        self, kind: str, entries: Iterable[Entry] = (), group: str | None = None, *, ordered: bool = False
    ) -> None:
        self.kind = kind
        self.group = group
        self.ordered = ordered
        self._entries: dict[str, Entry] = {}
        self._builtin: set[str] = set()
        self._plugins_read = group is None
        for e in entries:
            self.add(e)
            self._builtin.add(e.name)

    # -- registering ----------------------------------------------------------------------
    def add(self, entry: Entry, *, replace: bool = False) -> None:
        """Register ``entry``; a taken name raises :class:`InputDataError` unless ``replace``
        (registering an equal entry again is a no-op)."""
        old = self._entries.get(entry.name)
        if old is not None and old != entry and not replace:
            raise InputDataError(f"{self.kind} {entry.name!r} is already registered (pass replace=True)")
        self._entries[entry.name] = entry

    def register(
        self, name: str, factory: Callable[..., T] | str, *, replace: bool = False, **meta: Any
    ) -> None:
        """Register ``factory`` (a callable or ``"module:attr"``) under ``name``; ``meta``: the
        other fields of :class:`Entry` (``label``, ``color``, ...)."""
        if not isinstance(name, str) or not _NAME.match(name):
            raise InputDataError(f"invalid {self.kind} name {name!r} (lower case letters, digits, _ . + -)")
        self.add(Entry(name, factory, **meta), replace=replace)

    def _read_plugins(self) -> None:
        if self._plugins_read:
            return
        self._plugins_read = True
        from importlib.metadata import entry_points

        for ep in entry_points(group=self.group):
            if ep.name in self._builtin:
                continue  # a plugin cannot replace a built-in method
            self._entries.setdefault(ep.name, Entry(ep.name, ep.value, extra={"plugin": True}))

    # -- looking up -----------------------------------------------------------------------
    def names(self, tag: str | None = None) -> list[str]:
        """The registered names (those tagged ``tag`` if given), sorted or in the order
        registered; plugins included, nothing is imported."""
        self._read_plugins()
        names = [n for n, e in self._entries.items() if tag is None or tag in e.tags]
        return names if self.ordered else sorted(names)

    def __contains__(self, name: object) -> bool:
        self._read_plugins()
        return name in self._entries

    def __iter__(self) -> Iterator[str]:
        return iter(self.names())

    def entry(self, name: str) -> Entry:
        """The entry of ``name``; a plugin's whose object is an :class:`Entry` is loaded for its
        label and colour.  Unknown names raise :class:`UnsupportedError` listing the known ones."""
        self._read_plugins()
        if name not in self._entries:
            known = ", ".join(self.names())
            raise UnsupportedError(f"unknown {self.kind} {name!r}; known {self.kind}s: {known}")
        e = self._entries[name]
        if e.extra.get("plugin") and isinstance(e.target, str):
            obj = self._import(e)
            e = replace(obj, name=name) if isinstance(obj, Entry) else replace(e, target=obj)
            self._entries[name] = e
        return e

    def label(self, name: str) -> str:
        """How figures and tables name ``name`` (the name itself when it is not registered)."""
        return self.entry(name).display if name in self else name

    def factory(self, name: str) -> Callable[..., T]:
        """The factory of ``name``, imported now if it was lazy."""
        e = self.entry(name)
        if isinstance(e.target, str):
            obj = self._import(e)
            target = obj.target if isinstance(obj, Entry) else obj
            if isinstance(target, str):
                raise UnsupportedError(f"{self.kind} {name!r}: {e.target} names another lazy entry")
            e = replace(e, target=target)
            self._entries[name] = e
        return e.target  # type: ignore[return-value]

    def create(self, name: str, **options: Any) -> T:
        """A new ``name`` built with ``options``, checked against the factory's signature
        (:func:`dgse.options.check_options`: unknown names and wrong types are errors)."""
        from dgse.options import check_options

        factory = self.factory(name)
        return factory(**check_options(f"{self.kind} {name!r}", factory, options))

    def accepts(self, name: str, option: str) -> bool:
        """Whether ``name``'s factory takes keyword ``option`` (False for unknown names)."""
        from dgse.options import accepts

        return name in self and accepts(self.factory(name), option)

    def _import(self, e: Entry) -> Any:
        module, _, attr = str(e.target).partition(":")
        try:
            obj: Any = importlib.import_module(module)
            for part in attr.split("."):
                obj = getattr(obj, part)
        except (ImportError, AttributeError) as err:
            raise UnsupportedError(f"{self.kind} {e.name!r} cannot be loaded here: {err}") from err
        return obj


def lazy_attributes(
    namespace: dict[str, Any], modules: dict[str, tuple[str, ...]]
) -> tuple[Callable[[str], Any], Callable[[], list[str]]]:
    """A package's module-level ``__getattr__`` and ``__dir__`` for names imported on first use.

    Args:
        namespace: the package's ``globals()``; a name, once imported, is kept in it, so
            the next use finds it without coming back here.
        modules: each module -> the names of it the package offers.

    Returns:
        ``(__getattr__, __dir__)``: the first imports the module of ``name`` and returns
        its ``name`` (:class:`AttributeError` for a name no module offers); the second
        lists the namespace and the package's ``__all__``.
    """
    package = namespace["__name__"]
    where = {name: module for module, names in modules.items() for name in names}

    def __getattr__(name: str) -> Any:
        module = where.get(name)
        if module is None:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        value = getattr(importlib.import_module(module), name)
        namespace[name] = value
        return value

    def __dir__() -> list[str]:
        return sorted(set(namespace) | set(namespace.get("__all__", ())))

    return __getattr__, __dir__
