"""evaluate() and the estimate / evaluate commands on two tiny solved cases with tiny networks.

One flow solve and two gas solves (``two_rooms``, 30 x 20 cells) shared by
the module; untrained base-width-4 networks on a 32 x 32 canvas.
"""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path

import numpy as np
import pytest
import typer

from dgse.belief.belief import Belief, normalize_source_probs
from dgse.belief.knowledge import KnowledgeUser
from dgse.cli.common import parse_params
from dgse.cli.main import main as models_main
from dgse.cli.models import register
from dgse.errors import InputDataError, UnsupportedError
from dgse.evaluation.evaluate import (
    draw_observations,
    evaluate,
    load_estimate,
    observation_seed,
    save_estimate,
    write_json,
)
from dgse.evaluation.metrics import METRIC_KEYS, evaluate_belief
from dgse.models.checkpoint import save_model
from dgse.physics.scenario import solve_cases
from dgse.sensing.noise import NoiseModel
from dgse.sensing.sensors import Observations
from dgse.world.case import Case
from tests.conftest import two_rooms
from tests.models.helpers import tiny_model

REQUIRED = (
    "sl_error_m_mean",
    "sl_error_m_median",
    "ce_mean",
    "cf_rmse_mean",
    "cf_nll_mean",
    "wf_rmse_mean",
    "wf_nll_mean",
    "seconds_per_estimate_median",
    "sl_error_m_std",
    "sl_error_m_count",
)
DGSE_KW = {"K": 2, "T": 2, "canvas_minimum": 32}


@pytest.fixture(scope="module")
def cases() -> list[Case]:
    return solve_cases(two_rooms(), 1.0, [((0.55, 0.45), 1.0), ((2.25, 1.45), 0.5)])


@pytest.fixture(scope="module")
def case_dir(cases, tmp_path_factory) -> Path:
    d = tmp_path_factory.mktemp("cases")
    for c in cases:
        c.save(d / f"{c.name}.npz")
    return d


@pytest.fixture(scope="module")
def checkpoint(tmp_path_factory) -> Path:
    return save_model(tiny_model("dgse-s"), tmp_path_factory.mktemp("model") / "tiny-s.safetensors")


class Recorder(KnowledgeUser):
    """A uniform-posterior estimator that records what it was given (no fields)."""

    name = "recorder"

    def __init__(self) -> None:
        self.seen: list[Observations] = []

    def estimate(self, occupancy: np.ndarray, resolution: float, observations: Observations) -> Belief:
        self.seen.append(observations)
        occ = np.asarray(occupancy)
        probs = normalize_source_probs(np.ones(occ.shape), occ)
        return Belief(occ, resolution, probs, info={"method": self.name})


def _strip_times(records: list[dict]) -> list[dict]:
    return [{k: v for k, v in r.items() if k != "seconds"} for r in records]


def test_result_structure_and_json(cases, tmp_path):
    result = evaluate(
        cases,
        "dgse-s",
        [5, 20],
        trials=2,
        seed=3,
        estimator_kwargs={"model": tiny_model("dgse-s"), **DGSE_KW},
    )
    assert result["format"] == "dgse-evaluation" and result["method"] == "dgse-s"
    assert result["cases"] == ["two_rooms_src0", "two_rooms_src1"] and result["observation_counts"] == [5, 20]
    assert len(result["per_case"]) == 2 * 2 * 2
    rec = result["per_case"][0]
    assert {"case", "n_obs", "trial", "seconds", *METRIC_KEYS} <= set(rec)
    assert rec["seconds"] > 0 and rec["sl_error_m"] >= 0 and rec["wf_nll"] is not None
    assert set(result["aggregate"]) == {"5", "20"}
    errors_20 = [r["sl_error_m"] for r in result["per_case"] if r["n_obs"] == 20]
    assert result["aggregate"]["20"]["sl_error_m_mean"] == pytest.approx(np.mean(errors_20))
    assert result["aggregate"]["20"]["sl_error_m_median"] == pytest.approx(np.median(errors_20))
    for agg in result["aggregate"].values():
        assert agg["n_estimates"] == 4 and agg["sl_error_m_count"] == 4
        for key in REQUIRED:
            assert agg[key] is not None, key
    assert (
        set(result["by_case"]) == set(result["cases"])
        and result["by_case"]["two_rooms_src1"]["20"]["n_estimates"] == 2
    )
    path = write_json(result, tmp_path / "out" / "r.json")
    loaded = json.loads(path.read_text())  # strict JSON
    assert loaded["aggregate"]["20"]["ce_mean"] == pytest.approx(result["aggregate"]["20"]["ce_mean"])


def test_same_observations_for_every_method_and_deterministic(cases):
    a, b = Recorder(), Recorder()
    ra = evaluate(cases, a, [5, 20], trials=2, seed=7)
    rb = evaluate(list(reversed(cases)), b, [20], trials=2, seed=7)  # other order and counts
    by_key_a = {(r["case"], r["n_obs"], r["trial"]): o for r, o in zip(ra["per_case"], a.seen, strict=True)}
    for r, o in zip(rb["per_case"], b.seen, strict=True):
        oa = by_key_a[(r["case"], r["n_obs"], r["trial"])]
        np.testing.assert_array_equal(o.cells, oa.cells)
        np.testing.assert_array_equal(o.gas, oa.gas)
        np.testing.assert_array_equal(o.wind, oa.wind)
    # different trials and seeds give different sensors
    assert not np.array_equal(a.seen[0].cells, a.seen[1].cells)
    other = draw_observations(cases[0], 5, seed=8, case_id="two_rooms_src0")
    assert not np.array_equal(other.cells, a.seen[0].cells)
    # missing fields are None, and so are their statistics
    assert ra["per_case"][0]["wf_rmse"] is None and ra["aggregate"]["5"]["wf_rmse_count"] == 0
    assert ra["aggregate"]["5"]["wf_rmse_mean"] is None
    # a DGSE-S run repeated with the same seed gives the same metrics
    kw = {"model": tiny_model("dgse-s"), **DGSE_KW}
    r1 = evaluate(cases[:1], "dgse-s", 10, trials=2, seed=1, estimator_kwargs=kw)
    r2 = evaluate(cases[:1], "dgse-s", 10, trials=2, seed=1, estimator_kwargs=kw)
    assert _strip_times(r1["per_case"]) == _strip_times(r2["per_case"])
    r3 = evaluate(cases[:1], "dgse-s", 10, trials=2, seed=2, estimator_kwargs=kw)
    assert _strip_times(r1["per_case"]) != _strip_times(r3["per_case"])


def test_inputs_directory_file_and_store(case_dir, cases, tmp_path):
    from dgse.data.store import DatasetStore

    rec = Recorder()
    r_dir = evaluate(case_dir, rec, [5], seed=0)
    assert r_dir["cases"] == ["two_rooms_src0", "two_rooms_src1"] and r_dir["cases_source"] == str(case_dir)
    r_file = evaluate(case_dir / "two_rooms_src1.npz", rec, [5], seed=0)
    assert r_file["cases"] == ["two_rooms_src1"]
    assert r_file["per_case"][0]["sl_error_m"] == r_dir["per_case"][1]["sl_error_m"]
    store = tmp_path / "ds.h5"
    with DatasetStore(store, "w") as s:
        s.import_cases([case_dir], split="test")
    r_store = evaluate(store, rec, [5], seed=0)
    assert r_store["split"] == "test" and len(r_store["cases"]) == 2
    assert r_store["cases"][0].endswith("_src0")
    with pytest.raises(InputDataError, match="no cases in split 'val'"):
        evaluate(store, rec, [5], split="val")


def test_bad_inputs(cases, tmp_path):
    rec = Recorder()
    with pytest.raises(InputDataError, match="no such file"):
        evaluate(tmp_path / "missing", rec, [5])
    with pytest.raises(InputDataError, match="no case files"):
        evaluate(tmp_path, rec, [5])
    with pytest.raises(UnsupportedError, match="unknown estimator 'nope'"):
        evaluate(cases, "nope", [5])
    n_free = int(cases[0].free.sum())
    with pytest.raises(InputDataError, match=f"only {n_free} free cells"):
        evaluate(cases, rec, [n_free + 1])
    with pytest.raises(InputDataError, match="positive integers"):
        evaluate(cases, rec, [0])
    with pytest.raises(InputDataError, match="trials"):
        evaluate(cases, rec, [5], trials=0)
    with pytest.raises(InputDataError, match="seed"):
        observation_seed(-1, "x", 5, 0)


def test_frames_are_read_at_random_times(cases):
    c = cases[0]
    frames = np.stack([np.zeros_like(c.concentration), 2.0 * c.concentration])
    fc = Case(
        c.occupancy, c.wind, c.concentration, c.source, c.resolution, {**c.meta, "frame_dt": 1.0}, frames
    )
    obs = draw_observations(fc, 40, seed=0, noise_model=NoiseModel.noiseless())
    assert obs.times is not None and ((obs.times >= 0) & (obs.times < 2.0)).all()
    expected = frames[np.floor(obs.times).astype(int), obs.cells[:, 0], obs.cells[:, 1]]
    np.testing.assert_allclose(obs.gas, expected, rtol=1e-6)
    # the cells and noise are those of the same case without frames
    steady = draw_observations(c, 40, seed=0, noise_model=NoiseModel.noiseless())
    np.testing.assert_array_equal(obs.cells, steady.cells)


def test_estimate_file_round_trip(cases, tmp_path):
    from dgse.estimators.dgse import DGSEEstimator

    est = DGSEEstimator(tiny_model("dgse-s"), seed=0, **DGSE_KW)
    obs = draw_observations(cases[0], 10, seed=0)
    belief = est.estimate(cases[0].occupancy, cases[0].resolution, obs)
    metrics = evaluate_belief(belief, cases[0])
    path = save_estimate(tmp_path / "b", belief, obs, metrics, {"note": "x"})
    assert path.suffix == ".npz"
    b2, o2, meta = load_estimate(path)
    np.testing.assert_array_equal(b2.source_probs, belief.source_probs)
    np.testing.assert_array_equal(b2.log_conc_var, belief.log_conc_var)
    np.testing.assert_array_equal(o2.cells, obs.cells)
    assert o2.noise == obs.noise and meta["extra"] == {"note": "x"}
    assert meta["metrics"]["sl_error_m"] == pytest.approx(metrics.sl_error_m)
    # a belief that keeps the reducible part of its variance apart (dgse-phys) keeps it in the file
    part = dataclasses.replace(belief, log_conc_var_reducible=0.5 * belief.log_conc_var)
    b3, _, _ = load_estimate(save_estimate(tmp_path / "c", part, obs))
    np.testing.assert_array_equal(b3.log_conc_var_reducible, part.log_conc_var_reducible)
    assert b2.log_conc_var_reducible is None


# -- command line -------------------------------------------------------------------------------
def _run(capsys, *args) -> tuple[int, str, str]:
    code = models_main([str(a) for a in args])
    out, err = capsys.readouterr()
    return code, out, err


def _assert_user_error(code: int, out: str, err: str, fragment: str) -> None:
    assert code == 2, (out, err)
    line = err.strip()
    assert "Traceback" not in out + err and line.startswith("error: ") and "\n" not in line, err
    assert fragment in line, line


def test_cli_estimate(case_dir, checkpoint, tmp_path, capsys):
    case = case_dir / "two_rooms_src0.npz"
    out = tmp_path / "belief.npz"
    code, stdout, err = _run(
        capsys,
        "estimate",
        case,
        "--observations",
        12,
        "--seed",
        4,
        "--method",
        "dgse-s",
        "--model",
        checkpoint,
        "-K",
        2,
        "-T",
        2,
        "-o",
        out,
    )
    assert code == 0, err
    assert "source estimate" in stdout and "error" in stdout and "s per estimate" in stdout
    belief, obs, meta = load_estimate(out)
    assert len(obs) == 12 and belief.method == "dgse-s" and meta["extra"]["case_id"] == "two_rooms_src0"
    with np.load(out) as d:
        assert {"source_probs", "wind_mean", "log_conc_var", "conc_mean_ppm", "obs_cells", "metrics"} <= set(
            d.files
        )
    # the observations are trial 0 of `dgse evaluate` with the same seed
    same = draw_observations(Case.load(case), 12, seed=4, case_id="two_rooms_src0")
    np.testing.assert_array_equal(obs.cells, same.cells)


def test_cli_evaluate(case_dir, checkpoint, tmp_path, capsys):
    out = tmp_path / "eval.json"
    code, stdout, err = _run(
        capsys,
        "evaluate",
        case_dir,
        "--method",
        "dgse-s",
        "--observations",
        5,
        10,
        "--trials",
        2,
        "--seed",
        1,
        "--model",
        checkpoint,
        "-K",
        1,
        "-T",
        2,
        "--json",
        out,
        "--no-progress",
    )
    assert code == 0, err
    assert "SL error" in stdout and "8 estimates" in stdout
    result = json.loads(out.read_text())
    assert result["observation_counts"] == [5, 10] and set(result["aggregate"]) == {"5", "10"}
    assert result["estimator_kwargs"]["K"] == 1 and result["estimator"]["settings"]["checkpoint"] == str(
        checkpoint
    )
    assert math.isfinite(result["aggregate"]["10"]["sl_error_m_mean"])


def test_cli_errors(case_dir, checkpoint, tmp_path, capsys):
    _assert_user_error(
        *_run(capsys, "estimate", tmp_path / "nope.npz", "-n", 5, "-o", tmp_path / "x.npz"), "no such file"
    )
    _assert_user_error(
        *_run(capsys, "evaluate", case_dir, "--method", "nope", "-n", 5, "--no-progress"),
        "unknown estimator 'nope'",
    )
    _assert_user_error(
        *_run(
            capsys,
            "evaluate",
            case_dir,
            "-n",
            100000,
            "--method",
            "dgse-s",
            "--model",
            checkpoint,
            "--no-progress",
        ),
        "free cells",
    )
    _assert_user_error(
        *_run(capsys, "evaluate", tmp_path / "missing", "-n", 5, "--method", "dgse-s", "--model", checkpoint),
        "no such file",
    )
    _assert_user_error(
        *_run(capsys, "evaluate", case_dir, "--method", "dgse-s", "--model", checkpoint), "--observations"
    )
    _assert_user_error(
        *_run(
            capsys,
            "estimate",
            case_dir / "two_rooms_src0.npz",
            "-n",
            5,
            "-o",
            tmp_path / "x.npz",
            "--plot",
            "f.xyz",
        ),
        "cannot write a figure",
    )
    _assert_user_error(
        *_run(
            capsys,
            "estimate",
            case_dir / "two_rooms_src0.npz",
            "-n",
            5,
            "-o",
            tmp_path / "x.npz",
            "--method",
            "dgse-s",
            "--model",
            tmp_path / "none.safetensors",
        ),
        "not found",
    )
    _assert_user_error(
        *_run(capsys, "evaluate", case_dir, "-n", 5, "--method", "nope", "-K", 3), "unknown estimator 'nope'"
    )
    _assert_user_error(
        *_run(capsys, "evaluate", case_dir, "-n", 5, "--method", "kdmv", "-K", 3), "-K does not apply to kdmv"
    )
    _assert_user_error(
        *_run(capsys, "evaluate", case_dir, "-n", 5, "--method", "adjoint"),
        "adjoint works at knowledge level 'openings' or 'wind', not 'map': give --knowledge openings",
    )
    _assert_user_error(
        *_run(capsys, "evaluate", case_dir, "-n", 5, "--knowledge", "all"), "unknown knowledge level 'all'"
    )


def test_register_and_params():
    app = typer.Typer()
    register(app)
    names = {c.name for c in app.registered_commands}
    assert names == {"estimate", "evaluate", "export-onnx"}
    assert parse_params(["K=3", "name=abc", "w=[1, 2]"]) == {"K": 3, "name": "abc", "w": [1, 2]}
    # the docs' "inf: off" must be typeable; nan stays a string, which the options' checks refuse
    assert parse_params(["e=inf", "f=-INF", "g=nan"]) == {"e": math.inf, "f": -math.inf, "g": "nan"}
    with pytest.raises(InputDataError):
        parse_params(["novalue"])
    # a dotted key names a field of a settings object; each part must be a name
    dotted = parse_params(["fusion.floor=0", "fusion.floor.map=0.1"])
    assert dotted == {"fusion.floor": 0, "fusion.floor.map": 0.1}
    for bad in ("fusion..floor=0", "fusion.=0", ".floor=0", "fusion.1x=0"):
        with pytest.raises(InputDataError, match="dotted names"):
            parse_params([bad])


def test_plot_belief(cases):
    from matplotlib.figure import Figure
    from matplotlib.quiver import Quiver

    from dgse.estimators.dgse import DGSEEstimator
    from dgse.viz.belief import plot_belief

    case = cases[0]
    obs = draw_observations(case, 15, seed=0)
    full = DGSEEstimator(tiny_model("dgse-p"), canvas_minimum=32).estimate(case.occupancy, 0.1, obs)
    fig = plot_belief(full, case, obs)
    assert isinstance(fig, Figure)
    maps = [ax for ax in fig.axes if ax.get_title()]
    assert len(maps) == 8 and "error" in maps[0].get_title()
    assert any(isinstance(c, Quiver) for c in maps[1].collections)  # wind arrows
    assert len(maps[0].collections) >= 1  # the sensors
    # no truth, no fields: the posterior only
    src_only = DGSEEstimator(tiny_model("dgse-o"), canvas_minimum=32).estimate(case.occupancy, 0.1, obs)
    assert len([ax for ax in plot_belief(src_only).axes if ax.get_title()]) == 1
    assert len([ax for ax in plot_belief(full).axes if ax.get_title()]) == 5
    other = Case(case.occupancy[:, :20], case.wind[:, :, :20], case.concentration[:, :20], (0.55, 0.45), 0.1)
    with pytest.raises(InputDataError, match="map"):
        plot_belief(full, other)
