"""A third-party package adds an estimator and a planner through entry points alone.

The test installs a tiny plugin (its module and a ``.dist-info`` folder with
``entry_points.txt``, what pip writes) on ``sys.path`` and runs it through
``dgse evaluate`` and ``dgse search`` without touching DGSE's own code.
"""

from __future__ import annotations

import json
import textwrap
from pathlib import Path

import numpy as np
import pytest

from dgse.cli.main import main
from dgse.estimators.registry import ESTIMATORS
from dgse.planning.planners import PLANNERS
from dgse.world.case import Case
from dgse.world.grid import Grid

PLUGIN = '''
"""A plugin: the uniform posterior, and a planner that goes to the nearest unmeasured cell."""

import numpy as np

from dgse.belief import Belief, KnowledgeUser, normalize_source_probs
from dgse.planning.planners import PlannerBase
from dgse.registry import Entry


class Uniform(KnowledgeUser):
    knowledge_levels = ("map", "openings", "wind")

    def __init__(self, floor: float = 0.0) -> None:
        self.floor = floor

    def estimate(self, occupancy, resolution, observations):
        p = normalize_source_probs(np.ones(np.shape(occupancy)), occupancy)
        return Belief(occupancy, resolution, p, info={"method": "uniform", "seconds": 0.0})


class Nearest(PlannerBase):
    name = "nearest"

    def should_stop(self, belief, history):
        return history.step >= 4

    def next_goal(self, belief, robot_cell, distances, history):
        d = np.where(history.measured | ~np.isfinite(distances), np.inf, distances)
        d[robot_cell] = np.inf
        if not np.isfinite(d).any():
            return None
        k = int(np.argmin(d))
        return (k // d.shape[1], k % d.shape[1])


UNIFORM = Entry("plugin-uniform", Uniform, label="Uniform (plugin)", color="#123456")
'''

ENTRY_POINTS = """
[dgse.estimators]
plugin-uniform = dgse_test_plugin:UNIFORM

[dgse.planners]
plugin-nearest = dgse_test_plugin:Nearest
"""


@pytest.fixture
def plugin(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    site = tmp_path / "site"
    (site / "dgse_test_plugin-0.1.dist-info").mkdir(parents=True)
    (site / "dgse_test_plugin.py").write_text(textwrap.dedent(PLUGIN))
    info = site / "dgse_test_plugin-0.1.dist-info"
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: dgse-test-plugin\nVersion: 0.1\n")
    (info / "entry_points.txt").write_text(ENTRY_POINTS)
    monkeypatch.syspath_prepend(str(site))
    for reg in (ESTIMATORS, PLANNERS):  # read the entry points again, restore afterwards
        monkeypatch.setattr(reg, "_entries", dict(reg._entries))
        monkeypatch.setattr(reg, "_plugins_read", False)


def _case(path: Path) -> Path:
    """A 2 x 1.5 m open room with a made-up smooth plume (no solve needed)."""
    grid = Grid((15, 20), 0.1)
    occ = np.zeros(grid.shape, np.uint8)
    occ[0, :] = occ[-1, :] = occ[:, 0] = occ[:, -1] = 1
    src = (1.45, 0.75)
    d2 = (grid.x[None, :] - src[0]) ** 2 + (grid.y[:, None] - src[1]) ** 2
    conc = np.where(occ == 0, 50.0 * np.exp(-d2 / 0.2), 0.0)
    wind = np.zeros((2, *grid.shape))
    wind[0][occ == 0] = 0.3
    Case(occ, wind, conc, np.array(src), 0.1).save(path)
    return path


def test_plugin_through_evaluate_and_search(plugin: None, tmp_path: Path, capsys) -> None:
    assert "plugin-uniform" in ESTIMATORS.names() and "plugin-nearest" in PLANNERS.names()
    assert ESTIMATORS.label("plugin-uniform") == "Uniform (plugin)"
    case = _case(tmp_path / "room.npz")
    out = tmp_path / "eval.json"
    code = main(
        [
            "evaluate",
            str(case),
            "--method",
            "plugin-uniform",
            "-n",
            "5",
            "--trials",
            "1",
            "--no-progress",
            "--json",
            str(out),
        ]
    )
    assert code == 0, capsys.readouterr()
    result = json.loads(out.read_text())
    assert result["method"] == "plugin-uniform"
    search = tmp_path / "search.json"
    code = main(
        [
            "search", str(case), "--method", "plugin-uniform", "--planner", "plugin-nearest",
            "--trials", "1", "--no-progress", "--json", str(search),
        ]
    )  # fmt: skip
    assert code == 0, capsys.readouterr()
    episodes = json.loads(search.read_text())
    text = json.dumps(episodes)
    assert "plugin-nearest" in text and "plugin-uniform" in text


def test_a_plugin_cannot_take_a_builtin_name(plugin: None, tmp_path: Path) -> None:
    info = next((tmp_path / "site").glob("*.dist-info"))
    (info / "entry_points.txt").write_text("[dgse.estimators]\ndgse-s = dgse_test_plugin:UNIFORM\n")
    assert "dgse-s" in ESTIMATORS.names()
    target = ESTIMATORS.entry("dgse-s").target
    assert target == "dgse.estimators.dgse:make_dgse_s" or target.__module__ == "dgse.estimators.dgse"
