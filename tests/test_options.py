"""User options of named components: unknown names and wrong types are clear errors."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import pytest

from dgse.errors import InputDataError, UnsupportedError
from dgse.estimators.registry import estimator_names, get_estimator
from dgse.options import check_options, options_from
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
