"""What an estimator is told about a scenario besides its readings: the prior knowledge.

Three levels, each adding to the one before (``LEVELS``):

* ``"map"``: the occupancy grid and its resolution (the paper's setting);
* ``"openings"``: plus the inlet and outlet segments, as a building plan shows
  vents and doors;
* ``"wind"``: plus a mean wind field on the map, as from the user's own CFD
  (GADEN users have one), and the inlet speed when it is known.  The
  openings may be unknown at this level (a 3-D CFD flow sliced to 2-D; an
  imported GADEN case states neither openings nor inlet speed).

A :class:`Knowledge` holds exactly what its level allows and nothing of the
scenario's truth besides (no concentration, no source).  Every estimator
states the levels it works at (:attr:`KnowledgeUser.knowledge_levels`) and is
handed a :class:`Knowledge` before the estimates on a map
(:meth:`KnowledgeUser.set_knowledge`); a level it cannot work at is an
:class:`~dgse.errors.UnsupportedError` that says which level it needs.  The
evaluation, search and benchmark loops build the knowledge from the case with
:meth:`Knowledge.from_case` and record its level in their results, so that
every comparison says who knew what.  A setting whose value depends on the level
(an estimator's default at ``map`` and at ``wind``) is a :class:`PerLevel`.

Example::

    k = Knowledge.from_case(case, "openings")
    est = get_estimator("adjoint", knowledge=k)      # or est.set_knowledge(k)
    belief = est.estimate(k.occupancy, k.resolution, observations)
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field, fields, is_dataclass
from typing import TYPE_CHECKING, Any, ClassVar, Generic, Literal, TypeVar

import numpy as np

from dgse.errors import InputDataError, UnsupportedError
from dgse.options import Settings
from dgse.world.case import WALL_WIND_TOLERANCE, wind_problem
from dgse.world.layout import Layout, Opening

if TYPE_CHECKING:
    from dgse.belief.estimator import Estimator
    from dgse.world.case import Case

__all__ = [
    "DEFAULT_LEVEL",
    "LEVELS",
    "Knowledge",
    "KnowledgeUser",
    "Level",
    "PerLevel",
    "check_level",
    "per_level",
    "require_level",
]

Level = Literal["map", "openings", "wind"]
#: The knowledge levels, from least to most.
LEVELS: tuple[Level, ...] = ("map", "openings", "wind")
#: The paper's setting, and the default of every command.
DEFAULT_LEVEL: Level = "map"


def check_level(level: str) -> Level:
    """``level`` if it is one of :data:`LEVELS`; else a clear :class:`InputDataError`."""
    if level not in LEVELS:
        raise InputDataError(f"unknown knowledge level {level!r}; one of {', '.join(LEVELS)}")
    return level  # type: ignore[return-value]


T = TypeVar("T")
U = TypeVar("U")


@dataclass(frozen=True)
class PerLevel(Settings, Generic[T]):
    """One value of a setting per knowledge level.

    Where a user gives one value (``-p fusion.floor=0.0``) it holds at every level
    (:meth:`from_value`); ``KEY.map=...`` sets one level's.

    Attributes:
        map, openings, wind: the value at each level.
    """

    map: T
    openings: T
    wind: T

    @classmethod
    def from_value(cls, value: T) -> PerLevel[T]:
        """``value`` at every level."""
        return cls(value, value, value)

    @classmethod
    def describe_option(cls, element: str) -> str:
        return f"{element} (one for every level; per level: .map, .openings, .wind)"

    def __getitem__(self, level: str) -> T:
        return getattr(self, check_level(level))

    def items(self) -> tuple[tuple[Level, T], ...]:
        """``((level, value), ...)`` in the order of :data:`LEVELS`."""
        return tuple((v, getattr(self, v)) for v in LEVELS)

    def apply(self, fn: Callable[[T], U]) -> PerLevel[U]:
        """``fn`` of every level's value."""
        return PerLevel(fn(self.map), fn(self.openings), fn(self.wind))


def per_level(value: PerLevel[T] | T) -> PerLevel[T]:
    """``value`` if it is a :class:`PerLevel`, else ``value`` at every level."""
    return value if isinstance(value, PerLevel) else PerLevel.from_value(value)


def require_level(estimator: Estimator, name: str, level: str) -> None:
    """Raise :class:`UnsupportedError` unless ``estimator`` works at knowledge ``level``.

    The message names the levels it works at and the option that gives one.
    """
    levels = tuple(estimator.knowledge_levels)
    if level in levels:
        return
    if not levels:
        raise UnsupportedError(f"{name} states no knowledge levels (derive it from KnowledgeUser)")
    need = " or ".join(repr(v) for v in levels)
    raise UnsupportedError(
        f"{name} works at knowledge level {need}, not {level!r}: give --knowledge {levels[0]}"
    )


def _frozen(a: np.ndarray) -> np.ndarray:
    a = np.array(a, copy=True)
    a.setflags(write=False)
    return a


@dataclass(frozen=True, eq=False)
class Knowledge:
    """Prior knowledge about one scenario at one level (module docstring).

    Attributes:
        level: ``"map"``, ``"openings"`` or ``"wind"``.
        occupancy: ``uint8 (H, W)`` map, 1 solid (read-only copy).
        resolution: cell size, m.
        inlets, outlets: the openings (``"openings"``: required; ``"wind"``: optional).
        wind: ``float64 (2, H, W)`` mean wind, m/s, 0 in solid cells (``"wind"`` only).
        inlet_velocity: the inlet speed in m/s when known (``"wind"`` only, optional).
        name: the scenario's name (for messages).
    """

    level: Level
    occupancy: np.ndarray
    resolution: float
    inlets: tuple[Opening, ...] = ()
    outlets: tuple[Opening, ...] = ()
    wind: np.ndarray | None = None
    inlet_velocity: float | None = None
    name: str = ""
    _layout: Layout | None = field(default=None, init=False, repr=False)

    def __post_init__(self) -> None:
        set_ = object.__setattr__
        check_level(self.level)
        occ = np.asarray(self.occupancy)
        if occ.ndim != 2 or min(occ.shape) < 1:
            raise InputDataError(f"knowledge: the map must be 2-D, got shape {occ.shape}")
        set_(self, "occupancy", _frozen((occ != 0).astype(np.uint8)))
        res = float(self.resolution)
        if not (res > 0 and math.isfinite(res)):
            raise InputDataError(f"knowledge: resolution must be positive (m), got {self.resolution}")
        set_(self, "resolution", res)
        set_(self, "inlets", tuple(self.inlets))
        set_(self, "outlets", tuple(self.outlets))
        has_openings = bool(self.inlets or self.outlets)
        if self.level == "map" and (has_openings or self.wind is not None or self.inlet_velocity is not None):
            raise InputDataError("knowledge at level 'map' is the map alone (no openings, wind, inlet speed)")
        if self.level == "openings":
            if not (self.inlets and self.outlets):
                raise InputDataError("knowledge at level 'openings' needs at least one inlet and one outlet")
            if self.wind is not None or self.inlet_velocity is not None:
                raise InputDataError("knowledge at level 'openings' holds no wind field or inlet speed")
        if has_openings:
            if not (self.inlets and self.outlets):
                raise InputDataError("knowledge: give both the inlets and the outlets, or neither")
            # a Layout checks that the openings lie on the map's edge
            layout = Layout(
                self.occupancy,
                self.inlets,
                self.outlets,
                resolution=self.resolution,
                name=self.name or "layout",
            )
            set_(self, "_layout", layout)
        if self.level == "wind":
            if self.wind is None:
                raise InputDataError("knowledge at level 'wind' needs a wind field (2, H, W), m/s")
            set_(self, "wind", _frozen(self.check_wind(self.wind)))
        if self.inlet_velocity is not None:
            v = float(self.inlet_velocity)
            if not (v > 0 and math.isfinite(v)):
                raise InputDataError(f"knowledge: inlet velocity must be positive, got {self.inlet_velocity}")
            set_(self, "inlet_velocity", v)

    def check_wind(self, wind: np.ndarray) -> np.ndarray:
        """``wind`` as ``float64 (2, H, W)``, checked against this map (shape, finite, no flow in walls)."""
        w = np.asarray(wind, dtype=np.float64)
        problem = wind_problem(self.occupancy, w, "wind field", WALL_WIND_TOLERANCE)
        if problem:
            raise InputDataError(problem)
        return w

    # -- constructors ------------------------------------------------------------------------
    @classmethod
    def from_case(cls, case: Case, level: str = DEFAULT_LEVEL) -> Knowledge:
        """What a robot is told about ``case`` at ``level``: never its concentration or source.

        ``"wind"`` takes the case's wind field (the stand-in for the user's CFD), its
        openings and its inlet speed where its ``meta`` states them (an imported GADEN
        scenario states neither: a slice of a 3-D flow, :mod:`dgse.physics.projection`).

        Raises:
            UnsupportedError: ``"openings"`` of a case that states none.
        """
        lv = check_level(level)
        base: dict[str, Any] = {"occupancy": case.occupancy, "resolution": case.resolution, "name": case.name}
        if lv == "map":
            return cls("map", **base)
        meta = case.meta
        if any(k in meta for k in ("inlet", "inlets")) or any(k in meta for k in ("outlet", "outlets")):
            layout = case.layout
            base.update(inlets=layout.inlets, outlets=layout.outlets)
        elif lv == "openings":
            raise UnsupportedError(
                f"case {case.name!r} states no openings (no inlet or outlet in its meta, as an imported "
                "GADEN scenario): give --knowledge map or wind"
            )
        if lv == "openings":
            return cls("openings", **base)
        v = meta.get("inlet_velocity")
        return cls("wind", wind=case.wind, inlet_velocity=None if v is None else float(v), **base)

    # -- queries -----------------------------------------------------------------------------
    @property
    def has_openings(self) -> bool:
        """True when the inlets and outlets are known."""
        return self._layout is not None

    @property
    def layout(self) -> Layout:
        """The map with its openings (a :class:`~dgse.world.layout.Layout`).

        Raises:
            UnsupportedError: the openings are not part of this knowledge.
        """
        if not self.has_openings or self._layout is None:
            raise UnsupportedError(
                f"the openings (inlets and outlets) are not known at knowledge level {self.level!r}"
            )
        return self._layout

    def covers(self, level: str) -> bool:
        """True when this knowledge includes everything of ``level``."""
        return LEVELS.index(self.level) >= LEVELS.index(check_level(level))

    def check_map(self, occupancy: np.ndarray, resolution: float, who: str = "estimator") -> None:
        """Raise :class:`InputDataError` unless ``occupancy``/``resolution`` are this knowledge's map."""
        occ = np.asarray(occupancy)
        if (
            occ.shape != self.occupancy.shape
            or not np.array_equal(occ != 0, self.occupancy != 0)
            or not math.isclose(float(resolution), self.resolution, rel_tol=1e-9)
        ):
            what = f" of {self.name!r}" if self.name else ""
            raise InputDataError(f"{who}: the map passed to estimate() is not the map of its knowledge{what}")

    def to_dict(self) -> dict[str, Any]:
        """A JSON summary: the level and what it included (no arrays)."""
        return {
            "level": self.level,
            "openings": self.has_openings,
            "wind_field": self.wind is not None,
            "inlet_velocity": self.inlet_velocity is not None,
        }


class KnowledgeUser:
    """What every estimator shares about knowledge: the levels it works at, and receiving it.

    Subclasses set :attr:`knowledge_levels` and, when they use more than the
    map, override :meth:`_use_knowledge` (called by :meth:`set_knowledge` after
    the level check).  Without a :meth:`set_knowledge` call an estimator
    knows the map it is given in ``estimate`` and nothing more.
    """

    #: The levels this estimator works at (a higher level it does not use is ignored).
    knowledge_levels: ClassVar[tuple[Level, ...]] = LEVELS
    #: The knowledge handed over last (None: the map given to ``estimate`` only).
    knowledge: Knowledge | None = None

    @property
    def name(self) -> str:
        """The estimator's name (its class's, unless the estimator says otherwise)."""
        return type(self).__name__

    #: The seed of the estimator's own random draws (None: fresh ones).  The evaluation and
    #: search loops set it before each estimate so that runs repeat; an estimator that draws
    #: nothing ignores it.
    seed: int | None = None

    def describe(self) -> dict[str, Any]:
        """The settings that make this estimator's estimates what they are, recorded with every
        result (an evaluation journal with other settings is refused): a dataclass estimator's
        fields, defaults included, without the knowledge and the seed, which are told per case;
        other estimators override this."""
        if not is_dataclass(self):
            return {}
        return {
            f.name: getattr(self, f.name)
            for f in fields(self)
            if f.init and not f.name.startswith("_") and f.name not in ("knowledge", "seed")
        }

    def set_knowledge(self, knowledge: Knowledge) -> None:
        """Use ``knowledge`` for the estimates on its map from now on.

        Raises:
            UnsupportedError: a level this estimator does not work at (the
                message names the levels it needs).
        """
        if not isinstance(knowledge, Knowledge):
            raise InputDataError(f"knowledge must be a Knowledge, got {type(knowledge).__name__}")
        require_level(self, self.name, knowledge.level)
        self._use_knowledge(knowledge)
        self.knowledge = knowledge

    def _use_knowledge(self, knowledge: Knowledge) -> None:
        """Take what this estimator uses from ``knowledge`` (default: nothing beyond the map)."""
