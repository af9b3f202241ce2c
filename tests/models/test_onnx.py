"""ONNX export: ONNX Runtime agrees with PyTorch (max abs difference < 1e-4) for every variant.

Tiny networks (base width 4, depth 2); graphs traced on one shape and run on
another (batch, canvas, K and T are dynamic).
"""

from __future__ import annotations

import numpy as np
import pytest
import torch

from dgse.errors import InputDataError
from dgse.models.inference import predict
from dgse.models.onnx_export import (
    DEFAULT_OPSET,
    check_onnx,
    example_inputs,
    export_modules,
    export_onnx,
    pipeline_reference,
)
from tests.models.helpers import tiny_model

onnx = pytest.importorskip("onnx")
ort = pytest.importorskip("onnxruntime")

TOL = 1e-4


def _session(path) -> ort.InferenceSession:
    opts = ort.SessionOptions()
    opts.intra_op_num_threads = 1
    opts.inter_op_num_threads = 1
    return ort.InferenceSession(str(path), sess_options=opts, providers=["CPUExecutionProvider"])


@pytest.mark.parametrize("variant", ["dgse-o", "dgse-p"])
def test_single_network(variant, tmp_path):
    model = tiny_model(variant)
    result = export_onnx(model, tmp_path / f"{variant}.onnx")
    assert result.export_variant == "pipeline" and len(result.paths) == 1
    proto = onnx.load(str(result.paths[0]))
    meta = {p.key: p.value for p in proto.metadata_props}
    assert meta["dgse_variant"] == variant and meta["stage"] == "pipeline"
    assert max(o.version for o in proto.opset_import if o.domain in ("", "ai.onnx")) >= DEFAULT_OPSET
    assert check_onnx(model, result) < TOL
    # a third shape, against predict
    x = example_inputs(export_modules(model)[0], batch=1, canvas=(24, 33), seed=5)["x"]
    inputs, ref = pipeline_reference(model, x)
    got = _session(result.paths[0]).run(None, {"x": inputs["x"].numpy()})
    assert len(got) == (1 if variant == "dgse-o" else 5)
    for r, g in zip(ref, got, strict=True):
        assert np.abs(r.numpy() - g).max() < TOL
    probs = got[0]
    assert probs.shape == (1, 24, 33) and abs(probs.sum() - 1.0) < 1e-5
    assert (probs[0][x[0, 4].numpy() < 0.5] == 0).all()  # exactly 0 off the valid region


def test_dgse_s_pipeline_matches_predict(tmp_path):
    model = tiny_model("dgse-s")
    result = export_onnx(model, tmp_path / "s.onnx", variant="pipeline")
    assert result.inputs == (("x", "eps_wind", "eps_logc"),)
    assert check_onnx(model, result) < TOL
    # K = 4, T = 1 on another canvas: the noise drawn as predict draws it gives predict's result
    x = example_inputs(export_modules(model)[0], batch=1, canvas=(19, 26), seed=9)["x"]
    inputs, ref = pipeline_reference(model, x, K=4, T=1, seed=3)
    got = _session(result.paths[0]).run(None, {k: v.numpy() for k, v in inputs.items()})
    for r, g in zip(ref, got, strict=True):
        assert np.abs(r.numpy() - g).max() < TOL


def test_dgse_s_stages_assemble_to_predict(tmp_path):
    model = tiny_model("dgse-s")
    result = export_onnx(model, tmp_path / "s.onnx", variant="stages")
    assert [p.name for p in result.paths] == ["s.wind.onnx", "s.conc.onnx", "s.source.onnx"]
    assert check_onnx(model, result) < TOL
    wind, conc, source = (_session(p) for p in result.paths)
    # run the documented recipe with predict's noise: replicas k * B + b, then (t * K + k) * B + b
    K, T, seed = 3, 2, 4
    x = example_inputs(export_modules(model)[0], batch=2, canvas=(21, 18), seed=2)["x"]
    B, _, H, W = x.shape
    g = torch.Generator().manual_seed(seed)
    eps_w = torch.randn((K, B, 2, H, W), generator=g).reshape(K * B, 2, H, W).numpy()
    eps_c = torch.randn((T, K, B, H, W), generator=g).reshape(T * K * B, H, W).numpy()
    xn = x.numpy()
    wm, wv = wind.run(None, {"x": xn})
    xk = np.concatenate([xn] * K)
    ws, cm, cv = conc.run(
        None,
        {
            "x": xk,
            "wind_mean": np.concatenate([wm] * K),
            "wind_var": np.concatenate([wv] * K),
            "eps_wind": eps_w,
        },
    )
    (probs,) = source.run(
        None,
        {
            "x": np.concatenate([xk] * T),
            "wind_sample": np.concatenate([ws] * T),
            "logc_mean": np.concatenate([cm] * T),
            "logc_var": np.concatenate([cv] * T),
            "eps_logc": eps_c,
        },
    )
    pred = predict(model, x, K, T, seed=seed)
    assert np.abs(probs.reshape(T * K, B, H, W).mean(0) - pred.source_probs.numpy()).max() < TOL
    mu = cm.reshape(K, B, H, W)
    mean = mu.mean(0)
    var = cv.reshape(K, B, H, W).mean(0) + ((mu - mean) ** 2).mean(0)
    assert np.abs(mean - pred.logc_mean.numpy()).max() < TOL
    assert np.abs(var - pred.logc_var.numpy()).max() < TOL
    assert np.abs(wv - pred.wind_var.numpy()).max() < TOL


def test_export_errors_and_checkpoint(tmp_path, capsys):
    from dgse.cli.main import main as models_main
    from dgse.models.checkpoint import save_model

    with pytest.raises(InputDataError, match="stages"):
        export_onnx(tiny_model("dgse-o"), tmp_path / "o.onnx", variant="stages")
    with pytest.raises(InputDataError, match="opset"):
        export_onnx(tiny_model("dgse-o"), tmp_path / "o.onnx", opset=13)
    with pytest.raises(InputDataError, match="variant"):
        export_onnx(tiny_model("dgse-o"), tmp_path / "o.onnx", variant="trt")
    ckpt = save_model(tiny_model("dgse-p"), tmp_path / "p.safetensors")
    code = models_main(["export-onnx", "--model", str(ckpt), "-o", str(tmp_path / "p.onnx")])
    out, err = capsys.readouterr()
    assert code == 0, err
    assert "max abs difference" in out and (tmp_path / "p.onnx").stat().st_size > 0
    code = models_main(
        ["export-onnx", "--model", str(tmp_path / "nope.safetensors"), "-o", str(tmp_path / "x.onnx")]
    )
    out, err = capsys.readouterr()
    assert code == 2 and err.strip().startswith("error: ") and "not found" in err
