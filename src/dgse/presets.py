"""Named methods as they were measured: an estimator and a planner with their options, per level.

A *method* is what a user asks for by name (``dgse search --method dgse-phys``) and
what every result of the toolkit reports: the estimator (a registered name) with its
options, and for active search the planner with its options, each possibly extended at
one knowledge level.  Every command (``dgse search``, ``evaluate``, ``estimate``,
``demo``, ``bench``) resolves a method here, so a name means one thing everywhere; a
user's ``-p``/``-P`` options are applied on top, and the resolved options are recorded
in the output.  Why each value: ``docs/decisions.md``.

Any registered estimator is a method too: without a preset here it runs with its own
defaults and the paper's utility planner.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from dgse.belief.knowledge import LEVELS, check_level
from dgse.sensing.sensors import MIN_SENSORS

__all__ = [
    "DEFAULT_METHOD",
    "NETWORK_METHOD",
    "PHYSICS_METHOD",
    "PRESETS",
    "PROTOCOL",
    "Preset",
    "ResolvedMethod",
    "SearchProtocol",
    "preset",
    "resolve",
]


@dataclass(frozen=True)
class SearchProtocol:
    """The paper's search protocol (Sec. V-D): what every search runs with unless told otherwise.

    Attributes:
        speed: the robot's speed, m/s.
        dwell: the time spent at a cell for one reading, s.
        time_limit: a search's time limit, s.
        min_start_distance: the least path length from a random start to the source, m (a start
            inside the 2 m success radius would make a trial trivial).
        sample_rate_hz: readings per second of travel while the robot drives from one goal
            to the next (:class:`dgse.search.robot.Robot`), besides the reading at each goal;
            None: readings only at the goals, as the paper's protocol.
    """

    speed: float = 0.5
    dwell: float = 3.0
    time_limit: float = 2000.0
    min_start_distance: float = 2.0
    sample_rate_hz: float | None = None


#: The protocol of every search, benchmark and command.
PROTOCOL = SearchProtocol()


@dataclass(frozen=True)
class Preset:
    """A named method: what it runs, with which options, at each knowledge level.

    Attributes:
        name: the method's name (a registered estimator's, or a combination's such as
            ``pf-infotaxis``).
        estimator: the registered estimator it runs.
        planner: the registered planner of its searches.
        label: how tables and figures name it (None: the estimator's label).
        color: its colour in figures (None: the estimator's).
        estimator_options: the estimator's options wherever the method runs.
        search_estimator_options: added to those in an active search.
        planner_options: the planner's options.
        at_level: per knowledge level, options added there: keys ``"estimator"``,
            ``"search_estimator"``, ``"planner"``.
        quick_options: estimator options of a quick benchmark run (``--quick``: smoke-test
            sizes), on top of the others.
    """

    name: str
    estimator: str
    planner: str = "utility"
    label: str | None = None
    color: str | None = None
    estimator_options: Mapping[str, Any] = field(default_factory=dict)
    search_estimator_options: Mapping[str, Any] = field(default_factory=dict)
    planner_options: Mapping[str, Any] = field(default_factory=dict)
    at_level: Mapping[str, Mapping[str, Mapping[str, Any]]] = field(default_factory=dict)
    quick_options: Mapping[str, Any] = field(default_factory=dict)

    def _extra(self, level: str, part: str) -> dict[str, Any]:
        return dict(self.at_level.get(level, {}).get(part, {}))

    def estimator_options_at(self, level: str, *, search: bool) -> dict[str, Any]:
        """The estimator's options at knowledge ``level`` (in a search when ``search``)."""
        out = {**self.estimator_options, **self._extra(level, "estimator")}
        if search:
            out.update({**self.search_estimator_options, **self._extra(level, "search_estimator")})
        return out

    def planner_options_at(self, level: str) -> dict[str, Any]:
        """The planner's options in a search at knowledge ``level``."""
        return {**self.planner_options, **self._extra(level, "planner")}

    @property
    def display(self) -> str:
        """The label, else the estimator's registry label."""
        if self.label is not None:
            return self.label
        from dgse.estimators.registry import ESTIMATORS

        return ESTIMATORS.label(self.estimator)

    @property
    def colour(self) -> str | None:
        """The colour, else the estimator's registry colour."""
        if self.color is not None:
            return self.color
        from dgse.estimators.registry import ESTIMATORS

        return ESTIMATORS.entry(self.estimator).color if self.estimator in ESTIMATORS else None


@dataclass(frozen=True)
class ResolvedMethod:
    """A method resolved at one knowledge level: the exact names and options that run."""

    method: str
    level: str
    estimator: str
    estimator_options: dict[str, Any]
    planner: str
    planner_options: dict[str, Any]

    def to_json(self) -> dict[str, Any]:
        """What an output file records of it."""
        return {
            "method": self.method,
            "knowledge": self.level,
            "estimator": self.estimator,
            "estimator_options": dict(self.estimator_options),
            "planner": self.planner,
            "planner_options": dict(self.planner_options),
        }


#: DGSE-S's entropy threshold for the shipped model, tuned on the validation split
#: (its posteriors are broader than the paper's model's, whose threshold is 0.65).
DGSE_S_ETA = 0.78

#: PMFS's filament simulations in a search, cheaper than the published ones (about 20 CPU-s
#: per estimate on two cores with those, 0.6 s with these): recorded iterations, warm-up,
#: first quadtree leaf.
PMFS_SEARCH: dict[str, int] = {"n_record": 50, "max_warmup": 100, "leaf_cells": 20}

#: The plain network, DGSE-S: the method the benchmark report compares every other
#: method with (its wins, losses and ratios are against this one).
NETWORK_METHOD = "dgse-s"
#: The physics method, DGSE-Phys: the default (:data:`DEFAULT_METHOD`), which the report
#: sets against the network and the other searches.
PHYSICS_METHOD = "dgse-phys"

#: The named methods.  The DGSE networks run the shipped weights with bf16 autocast where
#: the CPU computes bf16 natively (float32 elsewhere) and channels-last convolutions.
PRESETS: dict[str, Preset] = {
    p.name: p
    for p in (
        Preset(
            NETWORK_METHOD,
            "dgse-s",
            search_estimator_options={"model": "default", "dtype": "auto", "channels_last": True},
            planner_options={"stop.eta": DGSE_S_ETA, "stop.min_observations": MIN_SENSORS},
        ),
        Preset(
            PHYSICS_METHOD,
            "dgse-phys",
            "info",
            search_estimator_options={"fusion.floor": 0.0},
            at_level={
                "openings": {"search_estimator": {"evidence.effective_readings": math.inf}},
                "map": {
                    "search_estimator": {
                        "evidence.effective_readings": 100.0,
                        "evidence.effective_growth": 0.0,
                    },
                    "planner": {"deadline.estimate_radius_m": 1.0},
                },
            },
        ),
        Preset("dualmode", "dualmode", "dualmode", label="Dual-mode"),
        Preset("grgsl", "grgsl", "infotaxis"),
        Preset(
            "pmfs",
            "pmfs",
            "pmfs",
            search_estimator_options={"params": PMFS_SEARCH},
            quick_options={"params": {"n_record": 10, "max_warmup": 20, "leaf_cells": 30}},
        ),
        Preset("pf-infotaxis", "dualmode", "infotaxis", label="Infotaxis (PF)", color="#1f77b4"),
    )
}

#: The method a command runs when none is named: the one that finds sources at every level.
DEFAULT_METHOD: dict[str, str] = dict.fromkeys(LEVELS, PHYSICS_METHOD)


def preset(name: str) -> Preset:
    """The preset of method ``name``; a registered estimator without one runs with its own
    defaults and the utility planner.  Unknown names raise
    :class:`~dgse.errors.UnsupportedError` listing the known ones."""
    if name in PRESETS:
        return PRESETS[name]
    from dgse.estimators.registry import ESTIMATORS

    ESTIMATORS.entry(name)  # unknown: the registry's error
    return Preset(name, name)


def resolve(
    name: str | None,
    level: str,
    *,
    search: bool,
    planner: str | None = None,
    estimator_options: Mapping[str, Any] | None = None,
    planner_options: Mapping[str, Any] | None = None,
) -> ResolvedMethod:
    """Method ``name`` (None: :data:`DEFAULT_METHOD` of ``level``) at knowledge ``level``.

    Args:
        search: resolve for an active search (the search options of the estimator too).
        planner: another registered planner than the method's; its own defaults then
            apply (the preset's planner options belong to the preset's planner).
        estimator_options, planner_options: the user's options, applied last.
    """
    level = check_level(level)
    p = preset(DEFAULT_METHOD[level] if name is None else name)
    plan = p.planner if planner is None else planner
    plan_opts = p.planner_options_at(level) if plan == p.planner else {}
    return ResolvedMethod(
        method=p.name,
        level=level,
        estimator=p.estimator,
        estimator_options={**p.estimator_options_at(level, search=search), **(estimator_options or {})},
        planner=plan,
        planner_options={**plan_opts, **(planner_options or {})},
    )
