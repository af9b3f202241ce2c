"""GDM tuning on a tiny store (dgse.bench.gdm_tuning, `benchmarks/training.py gdm`): validation
split only, a loadable tuning file."""

from __future__ import annotations

import json
import runpy
from pathlib import Path

import numpy as np
import pytest

from dgse.bench.gdm_tuning import tune
from dgse.data.store import DatasetStore
from dgse.errors import InputDataError
from dgse.mapping import load_tuning
from dgse.mapping.gmrf import GGMRF
from dgse.world.case import Case

SCRIPT = Path(__file__).resolve().parents[2] / "benchmarks" / "training.py"


def _layout(name: str) -> list[Case]:
    """Two analytic plumes on a 12 x 16 map with a wall and a door (no solver needed)."""
    H, W, res = 12, 16, 0.1
    occ = np.zeros((H, W), np.uint8)
    occ[:, 8] = 1
    occ[4:8, 8] = 0
    free = occ == 0
    wind = np.zeros((2, H, W), np.float32)
    wind[0][free] = 0.8
    i, j = np.mgrid[0:H, 0:W]
    cases = []
    for k, (si, sj) in enumerate([(3, 3), (8, 12)]):
        conc = 100.0 * np.exp(-((i - si) ** 2 + (j - sj) ** 2) / 18.0)
        conc[~free] = 0
        meta = {
            "name": f"{name}_src{k}",
            "layout": name,
            "source_index": k,
            "width_m": W * res,
            "height_m": H * res,
            "inlet": {"side": "west", "start_m": 0.2, "end_m": 0.8},
            "outlet": {"side": "east", "start_m": 0.2, "end_m": 0.8},
            "inlet_velocity": 0.8,
            "release_rate_gps": 1.0,
        }
        cases.append(Case(occ, wind, conc, ((sj + 0.5) * res, (si + 0.5) * res), res, meta))
    return cases


@pytest.fixture(scope="module")
def store(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("gdm") / "tiny.h5"
    with DatasetStore(path, "w") as s:
        s.add_layout(_layout("valA"), "val")
        s.add_layout(_layout("testA"), "test")
        s.fixed_configurations("val", n_per_env=2, seed=3)
    return path


def test_tuning_writes_a_loadable_file_from_the_validation_split(store, tmp_path):
    script = runpy.run_path(str(SCRIPT), run_name="training")
    grid = {
        "kdmv": {"sigma": [0.1, 0.38]},
        "kdmvw": {"sigma": [0.38], "gamma": [0.33]},
        "ggmrf": {"sigma_r": [0.3, 1.128]},
        "gwgmrf": {"sigma_r": [1.128]},
        "gabp": {"lambda_p": [0.5]},
    }
    (tmp_path / "grid.json").write_text(json.dumps(grid))
    out = tmp_path / "gdm_tuning.json"
    args = [str(store), "--out", str(out), "--grid", str(tmp_path / "grid.json"), "--configs-per-env", "1"]
    assert script["main"](["gdm", *args]) == 0
    doc = json.loads(out.read_text())
    assert doc["split"] == "val" and doc["n_samples"] == 2  # 2 val environments x 1 configuration
    assert set(doc["methods"]) == set(grid)
    assert doc["methods"]["kdmv"]["sigma"] in (0.1, 0.38)
    assert all(len(doc["search"][m]) == n for m, n in [("kdmv", 2), ("ggmrf", 2), ("gabp", 1)])
    assert doc["search"]["ggmrf"][0]["nll"] is not None and doc["search"]["kdmv"][0]["nll"] is None
    tuned = load_tuning(out)
    assert GGMRF(tuning=out).params.sigma_r == tuned["ggmrf"]["sigma_r"]


def test_random_observations_are_seeded(store):
    grid = {"ggmrf": {"sigma_r": [1.128]}}
    kw = dict(mode="random", counts=(10, 20), seed=4)
    a = tune(store, ["ggmrf"], grid, **kw)
    b = tune(store, ["ggmrf"], grid, **kw)
    assert a["n_samples"] == 4
    assert [(r["rmse"], r["nll"]) for r in a["search"]["ggmrf"]] == [
        (r["rmse"], r["nll"]) for r in b["search"]["ggmrf"]
    ]
    with pytest.raises(InputDataError, match="unknown method"):
        tune(store, ["nope"], grid)
