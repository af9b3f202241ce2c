"""User options of named components: unknown names and wrong types are clear errors."""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from typing import Literal

import pytest

from dgse.belief.knowledge import PerLevel
from dgse.errors import InputDataError, UnsupportedError
from dgse.estimators.registry import estimator_names, get_estimator
from dgse.options import (
    Settings,
    accepts,
    check_number,
    check_options,
    check_positive_numbers,
    check_switch,
    check_whole,
    options_from,
)
from dgse.planning.planners import get_planner, planner_names


@dataclass
class _Thing:
    n: int = 1
    scale: float = 1.0
    flag: bool = False
    mode: Literal["a", "b"] = "a"
    limit: float | None = None
    widths: tuple[float, ...] = (1.0,)


@options_from(_Thing, drop=("flag",), extra={"path": str})
def _make_thing(**kwargs):
    return _Thing(**kwargs)


def test_check_options_converts_and_rejects():
    assert check_options("x", _Thing, {"n": 3.0, "scale": 2, "limit": None}) == {
        "n": 3,
        "scale": 2.0,
        "limit": None,
    }
    assert check_options("x", _Thing, {"widths": [1, 2]}) == {"widths": [1.0, 2.0]}
    cases = [
        ({"nn": 1}, r"unknown x option\(s\) nn; known: flag, limit, mode, n, scale, widths"),
        ({"n": "abc"}, r"x: option n='abc' must be an integer"),
        ({"n": 1.5}, "must be an integer"),
        ({"n": True}, "must be an integer"),
        ({"scale": "1e-3x"}, "must be a number"),
        ({"flag": 1}, "must be true or false"),
        ({"mode": "c"}, r"must be one of 'a', 'b'"),
        ({"limit": "none"}, "must be a number or None"),
        ({"widths": "1,2"}, "must be a list"),
        ({"widths": [1, "a"]}, "must be a list"),
    ]
    for options, message in cases:
        with pytest.raises(InputDataError, match=message):
            check_options("x", _Thing, options)


@dataclass(frozen=True)
class _Noise(Settings):
    floor: PerLevel[float] = PerLevel(0.5, 0.2, 0.1)
    levels: tuple[float, ...] = (0.1, 0.5)
    robust: bool = True

    def __post_init__(self):
        if not all(v >= 0 for _, v in self.floor.items()):
            raise InputDataError(f"noise.floor must be >= 0, got {self.floor}")
        self._set("levels", tuple(self.levels))


@dataclass(frozen=True)
class _Evidence(Settings):
    noise: _Noise = field(default_factory=_Noise)
    q_max: float | None = 5.0


@dataclass
class _Component:
    evidence: _Evidence = field(default_factory=_Evidence)
    n: int = 1


def test_dotted_keys_set_the_fields_of_settings_objects():
    """``evidence.q_max=2`` sets that field on the default; nested keys reach nested settings and
    the levels of a :class:`PerLevel`; a mapping under the plain name means the same; a
    settings object given whole is the base the dotted keys apply to."""
    got = check_options("c", _Component, {"evidence.q_max": 2, "n": 3})
    assert got == {"evidence": _Evidence(q_max=2.0), "n": 3}
    assert isinstance(got["evidence"].q_max, float)
    got = check_options("c", _Component, {"evidence.noise.floor": 0, "evidence.noise.levels": [1, 2]})
    assert got["evidence"].noise == _Noise(floor=PerLevel(0.0, 0.0, 0.0), levels=(1.0, 2.0))
    assert got["evidence"].q_max == 5.0  # the default's other fields stay
    got = check_options("c", _Component, {"evidence.noise.floor.wind": 0.3})
    assert got["evidence"].noise.floor == PerLevel(0.5, 0.2, 0.3)
    mapped = check_options("c", _Component, {"evidence": {"noise": {"floor": {"wind": 0.3}}}})
    assert mapped == got
    given = _Evidence(q_max=None)
    on_given = check_options("c", _Component, {"evidence": given, "evidence.noise.robust": False})
    assert on_given["evidence"] == _Evidence(noise=_Noise(robust=False), q_max=None)
    assert accepts(_Component, "evidence.noise.floor.map") and accepts(_Component, "n")
    assert not accepts(_Component, "evidence.noise.flor") and not accepts(_Component, "n.x")


@pytest.mark.parametrize(
    ("options", "message"),
    [
        ({"evidence.qmax": 1}, r"option\(s\) evidence.qmax; known: evidence.noise, evidence.q_max$"),
        ({"evidence.noise.flor": 1}, r"option\(s\) evidence.noise.flor; known: evidence.noise.floor, "),
        ({"evidence.noise.floor.moon": 1}, r"evidence.noise.floor.moon; known: evidence.noise.floor.map, "),
        ({"evidenc.q_max": 1}, r"option\(s\) evidenc.q_max; known: evidence.noise, evidence.q_max, n$"),
        ({"n.x": 1}, r"option\(s\) n.x; known:"),
        ({"evidence.q_max": "big"}, r"c: option evidence.q_max='big' must be a number or None"),
        ({"evidence.noise.robust": "no"}, r"option evidence.noise.robust='no' must be true or false"),
        ({"evidence.noise.floor": "x"}, r"noise.floor='x' must be a number \(one for every level"),
        ({"evidence": 3}, r"option evidence=3 must be a _Evidence"),
        ({"evidence.noise.floor.map": -1.0}, r"noise.floor must be >= 0"),
    ],
)
def test_dotted_keys_are_checked(options, message):
    """Unknown fields, at any depth, list the valid keys there; wrong types name the dotted key;
    the settings object's own check runs."""
    with pytest.raises(InputDataError, match=message):
        check_options("c", _Component, options)


def test_options_from_reads_the_target():
    assert check_options("y", _make_thing, {"n": 2, "path": "p"}) == {"n": 2, "path": "p"}
    with pytest.raises(InputDataError, match=r"unknown y option\(s\) flag; known: limit, .*path"):
        check_options("y", _make_thing, {"flag": True})


@pytest.mark.parametrize("name", estimator_names())
def test_every_estimator_rejects_an_unknown_option(name):
    with pytest.raises(InputDataError, match=rf"unknown (estimator '{name}'|{name}) option\(s\) foo; known:"):
        get_estimator(name, foo=1)


@pytest.mark.parametrize("name", planner_names())
def test_every_planner_rejects_an_unknown_option(name):
    with pytest.raises(InputDataError, match=r"foo"):
        get_planner(name, foo=1)


@pytest.mark.parametrize(
    ("name", "options", "message"),
    [
        ("dgse-s", {"K": "abc"}, r"option K='abc' must be an integer"),
        ("dgse-o", {"T": 2.5}, "must be an integer"),
        ("dgse-s", {"channels_last": "yes"}, "must be true or false"),
        ("kdmv", {"sigma": "abc"}, r"kdmv: option sigma='abc' must be a number"),
        ("adjoint", {"q_max": "lots"}, "must be a number or None"),
        ("dualmode", {"n_particles": "many"}, "must be an integer"),
    ],
)
def test_option_types_are_checked(name, options, message):
    with pytest.raises(InputDataError, match=message):
        get_estimator(name, **options)


def test_devices_this_installation_lacks_are_clear_errors():
    import torch

    with pytest.raises(InputDataError, match="unknown device 'gpu': use cpu, cuda"):
        get_estimator("dgse-s", device="gpu")
    if not torch.cuda.is_available():
        with pytest.raises(UnsupportedError, match="use --device cpu"):
            get_estimator("dgse-s", device="cuda")
    assert str(get_estimator("dgse-s", device="cpu", K=2).device) == "cpu"


def test_field_checks_pass_good_values_and_name_the_key_of_bad_ones():
    assert check_switch("a.on", False) is False
    assert check_whole("a.n", 3.0, 1) == 3 and isinstance(check_whole("a.n", 3.0, 1), int)
    assert check_number("a.x", 1, low=0.0, high=1.0) == 1.0
    assert check_positive_numbers("a.v", [1, 2.5]) == (1.0, 2.5)
    bad = [
        (check_switch, ("a.on", "false"), "a.on must be true or false"),
        (check_whole, ("a.n", True, 0), "a.n must be an integer >= 0"),
        (check_whole, ("a.n", 2.5, 0), "a.n must be an integer >= 0"),
        (check_whole, ("a.n", 0, 1), "a.n must be an integer >= 1"),
        (check_number, ("a.x", 0.0), "a.x must lie in (0, 1]"),
        (check_number, ("a.x", float("nan")), "a.x must lie in (0, 1]"),
        (check_positive_numbers, ("a.v", [1.0, 0.0], " m/s"), "a.v must be positive numbers m/s"),
        (check_positive_numbers, ("a.v", ["x"]), "a.v must be positive numbers"),
        (check_positive_numbers, ("a.v", []), "a.v must be positive numbers"),
    ]
    for check, args, message in bad:
        kwargs = {"low": 0.0, "high": 1.0, "open_low": True} if check is check_number else {}
        with pytest.raises(InputDataError, match=re.escape(message)):
            check(*args, **kwargs)
