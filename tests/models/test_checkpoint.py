"""Checkpoints: safetensors round trip, metadata, and clear errors for bad files."""

from __future__ import annotations

import json

import pytest
import torch
from safetensors.torch import load_file, save_file

from dgse.errors import InputDataError
from dgse.models.checkpoint import (
    CheckpointError,
    load_checkpoint,
    load_model,
    read_checkpoint_info,
    save_model,
)
from dgse.models.inference import predict
from tests.models.helpers import canvas_batch, tiny_model


@pytest.mark.parametrize("variant", ["dgse-o", "dgse-p", "dgse-s"])
def test_round_trip_identical_outputs(tmp_path, variant):
    model = tiny_model(variant, seed=3).eval()
    path = save_model(model, tmp_path / "sub" / "m.safetensors", training={"epochs": 3, "loss": 1.5})
    loaded, info = load_checkpoint(path, variant=variant)
    assert info.variant == variant and info.config == model.config
    assert info.training == {"epochs": 3, "loss": 1.5} and info.torch_version == torch.__version__
    assert not loaded.training  # eval mode
    x, _ = canvas_batch(2, (32, 32))
    a = predict(model, x, K=2, T=2, seed=0)
    b = predict(loaded, x, K=2, T=2, seed=0)
    assert torch.equal(a.source_probs, b.source_probs)
    if variant != "dgse-o":
        assert torch.equal(a.logc_var, b.logc_var)
    assert read_checkpoint_info(path).config == model.config
    assert list(tmp_path.joinpath("sub").iterdir()) == [path]  # no temporary files left


def test_missing_and_corrupt_files(tmp_path):
    with pytest.raises(CheckpointError, match="not found"):
        load_model(tmp_path / "nope.safetensors")
    with pytest.raises(CheckpointError, match="not a file"):
        load_model(tmp_path)
    junk = tmp_path / "junk.safetensors"
    junk.write_bytes(b"\x00\x01garbage" * 10)
    with pytest.raises(CheckpointError, match="safetensors"):
        load_model(junk)
    good = save_model(tiny_model("dgse-s"), tmp_path / "good.safetensors")
    truncated = tmp_path / "truncated.safetensors"
    truncated.write_bytes(good.read_bytes()[:-100])
    with pytest.raises(CheckpointError):
        load_model(truncated)
    assert issubclass(CheckpointError, InputDataError)


def test_wrong_variant_and_mismatched_tensors(tmp_path):
    path = save_model(tiny_model("dgse-p"), tmp_path / "p.safetensors")
    with pytest.raises(CheckpointError, match="expected 'dgse-s'"):
        load_model(path, variant="dgse-s")
    tensors = load_file(str(path))
    meta = {"format": "dgse-checkpoint", "format_version": "1", "variant": "dgse-p"}
    # config claims a wider network than the stored tensors
    wider = {**tiny_model("dgse-p").config.to_dict(), "base_width": 8}
    bad_shape = tmp_path / "shape.safetensors"
    save_file(tensors, str(bad_shape), metadata={**meta, "config": json.dumps(wider)})
    with pytest.raises(CheckpointError, match="wrong shape"):
        load_model(bad_shape)
    missing = tmp_path / "missing.safetensors"
    cfg = json.dumps(tiny_model("dgse-p").config.to_dict())
    save_file(dict(list(tensors.items())[1:]), str(missing), metadata={**meta, "config": cfg})
    with pytest.raises(CheckpointError, match="missing"):
        load_model(missing)
    plain = tmp_path / "plain.safetensors"
    save_file(tensors, str(plain))
    with pytest.raises(CheckpointError, match="not a DGSE checkpoint"):
        load_model(plain)
    bad_cfg = tmp_path / "cfg.safetensors"
    save_file(tensors, str(bad_cfg), metadata={**meta, "config": "{not json"})
    with pytest.raises(CheckpointError, match="config"):
        load_model(bad_cfg)
    nan = tmp_path / "nan.safetensors"
    first = next(iter(tensors))
    save_file({**tensors, first: tensors[first] * float("nan")}, str(nan), metadata={**meta, "config": cfg})
    with pytest.raises(CheckpointError, match="non-finite"):
        load_model(nan)


def test_training_metadata_must_be_json(tmp_path):
    with pytest.raises(CheckpointError, match="JSON"):
        save_model(tiny_model("dgse-o"), tmp_path / "x.safetensors", training={"bad": object()})
