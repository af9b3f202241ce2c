"""Training runs: the ``dgse train`` command, learning, resuming, stopping, configs and errors.

One tiny store (a 3 x 2 m two-room layout with two sources, as train and as
val split) and a tiny DGSE-S (base width 4, depth 2) on one thread; every
run is a few batches of 4 samples on the 100 x 100 canvas.
"""

from __future__ import annotations

import csv
import math
from dataclasses import replace
from pathlib import Path

import lightning as L
import pytest
import torch
import typer
import yaml
from typer.testing import CliRunner

from dgse.cli.train import register
from dgse.data.store import DatasetStore
from dgse.errors import InputDataError
from dgse.models import load_model, read_checkpoint_info
from dgse.physics.scenario import solve_cases
from dgse.training import (
    TrainConfig,
    load_config,
    localization_error,
    parse_duration,
    read_train_state,
    train,
)
from tests.conftest import two_rooms

torch.set_num_threads(1)

REPO = Path(__file__).resolve().parents[2]
CONFIGS = REPO / "configs" / "train"
TINY = CONFIGS / "tiny-test.yaml"


@pytest.fixture(scope="module")
def store(tmp_path_factory) -> Path:
    cases = solve_cases(two_rooms(), 1.3, [((0.55, 0.55), 0.5), ((2.45, 1.45), 2.0)])
    path = tmp_path_factory.mktemp("train-ds") / "tiny.h5"
    with DatasetStore(path, "w") as s:
        s.add_layout(cases, "train")
        s.add_layout(cases, "val")
        s.fixed_configurations("val", n_per_env=3, seed=1)
    return path


def _config(store: Path, out: Path, **kw) -> TrainConfig:
    return load_config(TINY, {"data": str(store), "out_dir": str(out), **kw})


def _history(path: Path) -> list[dict[str, str]]:
    with path.open() as fh:
        return list(csv.DictReader(fh))


def _cli(*args: str):
    app = typer.Typer()

    @app.command("other")
    def other() -> None:  # a second command keeps `train` a named sub-command
        pass

    register(app)
    res = CliRunner().invoke(app, ["train", *map(str, args)])
    res.flat = res.output.replace("\n", "")  # rich wraps long paths at the terminal width
    return res


# -- the command -----------------------------------------------------------------------------
def test_cli_fast_dev_run_writes_metrics_and_a_loadable_best_model(store, tmp_path):
    out = tmp_path / "run"
    res = _cli("--config", TINY, "--network", "dgse-s", "--data", store, "--out", out, "--fast-dev-run")
    assert res.exit_code == 0, res.output
    assert "metrics" in res.flat and str(out / "best.safetensors") in res.flat
    metrics = out / "logs" / "version_0" / "metrics.csv"
    rows = list(csv.DictReader(metrics.open()))
    assert any(r.get("val/source_loss") for r in rows) and any(r.get("train/loss_epoch") for r in rows)
    [row] = _history(out / "history.csv")
    assert row["epoch"] == "0" and row["global_step"] == "2" and row["best"] == "1"
    assert math.isfinite(float(row["val/loc_error_m"])) and float(row["val/loc_error_m"]) < 3.7
    model = load_model(out / "best.safetensors", variant="dgse-s")
    assert model.config.base_width == 4 and model.config.depth == 2
    info = read_checkpoint_info(out / "best.safetensors").training
    assert info["epoch"] == 0 and "val/source_loss" in info["val"] and info["data"] == str(store.resolve())
    saved = yaml.safe_load((out / "config.yaml").read_text())
    assert saved["model_overrides"] == {"base_width": 4, "depth": 2}

    # a fast dev run is no run to resume (a fresh run replaces it)
    again = _cli("--config", TINY, "--data", store, "--out", out, "--resume")
    assert again.exit_code == 2 and "state of a fast dev run" in again.flat
    assert "Traceback" not in again.output


def test_cli_help_and_user_errors(store, tmp_path):
    res = _cli("--help")
    assert res.exit_code == 0
    for opt in ("--resume", "--max-time", "--precision", "--devices", "--fast-dev-run", "--set"):
        assert opt in res.output
    bad = tmp_path / "bad.yaml"
    bad.write_text("model: dgse-s\nlearning_rate: 0.1\n")
    res = _cli("--config", bad, "--data", store, "--out", tmp_path / "x")
    assert res.exit_code == 2 and "learning_rate" in res.flat and str(bad) in res.flat
    res = _cli("--config", TINY, "--data", store, "--out", tmp_path / "x", "--batch-size", "0")
    assert res.exit_code == 2 and "batch_size" in res.flat
    res = _cli("--config", TINY, "--out", tmp_path / "x")
    assert res.exit_code == 2 and "--data" in res.flat
    res = _cli("--config", TINY, "--data", tmp_path / "missing.h5", "--out", tmp_path / "x")
    assert res.exit_code == 2 and "missing.h5" in res.flat
    res = _cli("--config", TINY, "--data", store, "--out", tmp_path / "none", "--resume")
    assert res.exit_code == 2 and "nothing to resume" in res.flat
    assert res.flat.startswith("error: nothing to resume")  # nothing else is printed


# -- learning and resuming -------------------------------------------------------------------
class _SeeResume(L.Callback):
    """Records the loop position and optimizer state at the first epoch start."""

    def __init__(self) -> None:
        self.seen: tuple[int, int] | None = None
        self.optimizer: dict | None = None

    def on_train_epoch_start(self, trainer, pl_module) -> None:
        if self.seen is None:
            self.seen = (trainer.current_epoch, trainer.global_step)
            state = trainer.optimizers[0].state_dict()["state"]  # live tensors: copy them
            self.optimizer = {i: {k: v.clone() for k, v in st.items()} for i, st in state.items()}


def test_tiny_model_learns_and_resume_continues_exactly(store, tmp_path):
    # 8 samples per epoch (2 environments x 4 configurations), batches of 4
    straight = train(_config(store, tmp_path / "a", epochs=4))
    assert straight.stop_reason == "max_epochs" and straight.epochs_done == 4 and straight.global_step == 8
    loss = [float(r["train/loss"]) for r in _history(straight.history_csv)]
    assert loss[-1] < 0.5 * loss[0] and loss == sorted(loss, reverse=True)

    first = train(_config(store, tmp_path / "b", epochs=2))
    saved = read_train_state(first.last_path)
    assert saved.next_epoch == 2 and saved.global_step == 4
    assert {"exp_avg", "exp_avg_sq", "step"} <= set(saved.optimizer_state["state"][0])
    see = _SeeResume()
    resumed = train(_config(store, tmp_path / "b", epochs=4), resume=True, callbacks=[see])
    assert see.seen == (2, 4)  # the next epoch, with the steps done
    assert see.optimizer is not None
    for pid, st in saved.optimizer_state["state"].items():
        for name, t in st.items():
            assert torch.equal(see.optimizer[pid][name], t), (pid, name)
    assert resumed.epochs_done == 4 and resumed.global_step == 8
    # epochs are seeded per epoch: an interrupted and resumed run is the uninterrupted run
    a, b = read_train_state(straight.last_path), read_train_state(resumed.last_path)
    assert all(torch.equal(a.model_state[k], b.model_state[k]) for k in a.model_state)
    assert [r["epoch"] for r in _history(resumed.history_csv)] == ["0", "1", "2", "3"]
    assert resumed.best_score == pytest.approx(straight.best_score)

    # nothing left to do; the export is the best model
    export = str(tmp_path / "m.safetensors")
    done = train(_config(store, tmp_path / "b", epochs=4, export=export), resume=True)
    assert done.stop_reason == "already_done" and done.export_path is not None
    exported = read_checkpoint_info(done.export_path).training
    assert exported["epoch"] == resumed.best_epoch and exported["selection"] == "lowest val/source_loss"


def test_time_budget_stops_cleanly_and_resume_goes_on(store, tmp_path):
    cfg = _config(store, tmp_path / "t", epochs=3, max_time=1e-3)
    stopped = train(cfg)
    assert stopped.stop_reason == "max_time" and stopped.epochs_done == 1 and stopped.global_step == 1
    [row] = _history(stopped.history_csv)
    assert row["partial"] == "1" and row["val/source_loss"]  # validated and saved at the stop
    state = read_train_state(stopped.last_path)
    assert state.meta["partial_epoch"] and state.meta["stop_reason"] == "max_time"
    resumed = train(cfg.replace(max_time=None, epochs=2), resume=True)
    assert resumed.stop_reason == "max_epochs" and resumed.epochs_done == 2 and resumed.global_step == 3


def test_bad_resume_files_are_clear_errors(store, tmp_path):
    out = tmp_path / "r"
    export = str(tmp_path / "last-model.safetensors")
    train(_config(store, out, epochs=1, val_configs_per_env=0, export=export))
    assert not (out / "best.safetensors").exists()  # no validation, no best ...
    assert load_model(tmp_path / "last-model.safetensors").config.base_width == 4  # ... export = last
    with pytest.raises(InputDataError, match="already holds a training run"):
        train(_config(store, out, epochs=2))  # no accidental restart over a run
    with pytest.raises(InputDataError, match=r"other settings \(lr: run 0.0005, now 0.001\)"):
        train(_config(store, out, epochs=2, lr=1e-3), resume=True)
    with pytest.raises(InputDataError, match="model_config"):
        train(_config(store, out, epochs=2, **{"model_overrides.base_width": 6}), resume=True)
    last = out / "last.safetensors"
    last.write_bytes(last.read_bytes()[:200])
    with pytest.raises(InputDataError, match="not a readable safetensors file"):
        train(_config(store, out, epochs=2), resume=True)
    best_model = tmp_path / "last-model.safetensors"  # a model checkpoint is no training state
    with pytest.raises(InputDataError, match="not a DGSE training state"):
        read_train_state(best_model)


# -- configs and helpers -----------------------------------------------------------------------
def test_checked_in_configs():
    paper = load_config(CONFIGS / "paper.yaml")
    assert (paper.model, paper.preset, paper.batch_size, paper.epochs) == ("dgse-s", "paper", 300, 100)
    assert (paper.lr, paper.weight_decay) == (5e-4, 1e-4)
    lw = paper.loss_weights
    assert (lw.wind, lw.conc, lw.source) == (1.0, 1.0, 0.05)
    assert (paper.configs_per_env, paper.val_configs_per_env, paper.augment) == (30, 30, True)
    cpu = load_config(CONFIGS / "cpu-small.yaml")
    assert cpu.preset == "small" and 32 <= cpu.batch_size <= 64 and cpu.max_time_s is not None
    assert cpu.configs_per_env < 30 and cpu.accelerator == "cpu"
    sizes = load_config(CONFIGS / "cpu-small-sizes.yaml")  # fine-tunes the shipped weights
    assert sizes.init == "default" and sizes.model_config() == cpu.model_config() and sizes.lr < cpu.lr
    tiny = load_config(TINY)
    assert tiny.model_config().base_width == 4 and tiny.model_config().depth == 2
    defaults = paper.to_dict() | {"out_dir": "runs/dgse", "num_workers": 0}
    assert TrainConfig() == TrainConfig.from_dict(defaults)  # paper.yaml spells out the defaults


def test_config_errors_name_the_key(tmp_path):
    with pytest.raises(InputDataError, match=r"unknown training config key.*foo"):
        TrainConfig.from_dict({"foo": 1})
    with pytest.raises(InputDataError, match="precision"):
        load_config(None, {"precision": "8"})
    with pytest.raises(InputDataError, match=r"model_overrides.*widht"):
        load_config(None, {"model_overrides.widht": 3})
    with pytest.raises(InputDataError, match=r"loss_weights.*sourc"):
        load_config(None, {"loss_weights": {"sourc": 1}})
    with pytest.raises(InputDataError, match="max_time"):
        load_config(None, {"max_time": "1:99:00"})
    assert load_config(None, {"lr": "1e-3", "precision": 32}).lr == 1e-3
    assert parse_duration("1:00:00:01") == 86401.0 and parse_duration(90) == 90.0


def test_localization_error_is_distance_of_the_mean_position():
    probs = torch.zeros(2, 4, 5)
    probs[0, 1, 2] = 1.0  # exactly the true cell
    probs[1, 0, 0] = probs[1, 0, 4] = 0.5  # mean at (row 0, col 2); true cell (row 3, col 2)
    err = localization_error(probs, torch.tensor([1 * 5 + 2, 3 * 5 + 2]), cell_size=0.1)
    assert err.tolist() == pytest.approx([0.0, 0.3])


def test_init_starts_a_fresh_run_from_given_weights(store, tmp_path):
    """Fine-tuning: with zero learning rate the run's weights are exactly the given ones."""
    first = train(_config(store, tmp_path / "a", epochs=1, limit_train_batches=1, progress_bar=False))
    assert first.best_path is not None
    src = load_model(first.best_path, variant="dgse-s")
    cfg = _config(
        store, tmp_path / "b", epochs=1, limit_train_batches=1, progress_bar=False, init=str(first.best_path)
    )
    tuned = train(replace(cfg, lr=1e-12, weight_decay=0.0))
    got = load_model(tuned.best_path, variant="dgse-s").state_dict()
    for name, w in src.state_dict().items():
        assert torch.allclose(got[name], w, atol=1e-6), name
    fresh = train(_config(store, tmp_path / "c", epochs=1, limit_train_batches=1, progress_bar=False, seed=5))
    fresh_w = load_model(fresh.best_path, variant="dgse-s").state_dict()
    assert any(not torch.allclose(fresh_w[n], w, atol=1e-3) for n, w in src.state_dict().items())
    # another architecture, or no such file: a clear error before any step
    arch = {"base_width": 8, "depth": 2}
    wide = _config(store, tmp_path / "d", init=str(first.best_path), model_overrides=arch)
    with pytest.raises(InputDataError, match="another network"):
        train(wide)
    with pytest.raises(InputDataError, match="not a model file"):
        train(_config(store, tmp_path / "e", init=str(tmp_path / "missing.safetensors")))
    with pytest.raises(InputDataError, match=r"best\.safetensors is a model file"):
        train(_config(store, tmp_path / "f", init=str(first.last_path)))  # a training state


def test_bf16_on_a_cpu_without_it_warns(store, tmp_path, monkeypatch):
    import importlib

    train_module = importlib.import_module("dgse.training.train")  # the package exports a function `train`
    monkeypatch.setattr(train_module, "native_bf16", lambda device: False)
    cfg = _config(store, tmp_path / "bf16", precision="bf16-mixed", fast_dev_run=True)
    with pytest.warns(UserWarning, match="does not compute bf16 natively"):
        train(cfg)
