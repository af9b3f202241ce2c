"""Estimator commands: ``estimate``, ``evaluate``, ``export-onnx``.

:func:`register` attaches them to the ``dgse`` app at the top level:

* ``dgse estimate CASE.npz --observations N --seed S [--method dgse-s]
  [--model default|PATH] [-K 5 -T 5] -o BELIEF.npz [--plot FIG.png]``: one
  estimate from random observations of a case; writes the belief, the
  observations and the metrics (:func:`dgse.evaluation.evaluate.save_estimate`).
  The observations (and a DGSE-S estimator's sampling seed) are those of trial
  0 of ``dgse evaluate CASE.npz --seed S``.
* ``dgse evaluate CASES_DIR_OR_STORE --method M --observations N [N ...]
  --trials R --seed S [-o OUT.json] [--split test] [--model ...]``:
  :func:`dgse.evaluation.evaluate.evaluate`, a table of the aggregate per
  observation count, the JSON result.
* ``dgse export-onnx --model PATH -o OUT.onnx [--variant auto|pipeline|stages]``:
  :func:`dgse.models.onnx_export.export_onnx`, checked against PyTorch with
  ONNX Runtime.

``--model``, ``-K``, ``-T``, ``--device`` and ``--dtype`` configure the DGSE
estimators (``dgse-o``, ``dgse-p``, ``dgse-s``); any estimator takes
keyword arguments as ``--param KEY=VALUE`` (VALUE parsed as JSON, else a
string), so estimators registered later work unchanged.

Every error a user can cause prints one red line ``error: <message>`` and
exits with status 2 (:mod:`dgse.cli.common`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from enum import StrEnum
from pathlib import Path
from typing import Annotated, Any

import typer
from rich import box
from rich.markup import escape
from rich.table import Table

from dgse.belief.knowledge import DEFAULT_LEVEL, Knowledge, check_level
from dgse.cli.common import (
    KnowledgeOption,
    MethodOption,
    ParamOption,
    ProgressOption,
    ThreadsOption,
    check_output_file,
    console,
    journal_output,
    option_bundle,
    parse_params,
    path_text,
    restart_option,
    user_errors,
)
from dgse.errors import InputDataError
from dgse.files import atomic_path

__all__ = [
    "estimate_cmd",
    "evaluate_cmd",
    "export_onnx_cmd",
    "parse_params",
    "register",
]


class Dtype(StrEnum):
    """What ``--dtype`` takes (the DGSE estimators take more names from Python)."""

    float32 = "float32"
    bf16 = "bf16"
    auto = "auto"


_DTYPE_HELP = "DGSE precision: float32, bf16, or auto (bf16 where the CPU computes it natively)."
DtypeOption = Annotated[Dtype | None, typer.Option("--dtype", help=_DTYPE_HELP, show_default=False)]
# the options estimate and evaluate share
SeedOption = Annotated[int, typer.Option("--seed", "-s", help="Seed of the observations (>= 0).")]
_MODEL_HELP = "DGSE weights: 'default' (shipped with dgse) or a .safetensors checkpoint."
ModelOption = Annotated[str | None, typer.Option("--model", help=_MODEL_HELP)]
KOption = Annotated[int | None, typer.Option("-K", help="DGSE-S wind samples (default 5).")]
TOption = Annotated[int | None, typer.Option("-T", help="DGSE-S concentration samples (default 5).")]
DeviceOption = Annotated[str | None, typer.Option("--device", help="DGSE device (cpu, cuda, ...).")]


@dataclass(frozen=True)
class EstimatorOptions:
    """The estimator options ``estimate`` and ``evaluate`` share (:func:`~dgse.cli.common.option_bundle`).

    The shortcut options go to the estimators that take them (the DGSE networks:
    ``model``, ``K``, ``T``, ``device``, ``dtype``); any estimator takes keyword
    arguments as ``--param KEY=VALUE``; ``--threads`` sets PyTorch's CPU threads.
    """

    model: ModelOption = None
    k: KOption = None
    t: TOption = None
    device: DeviceOption = None
    dtype: DtypeOption = None
    params: ParamOption = None
    threads: ThreadsOption = None

    def resolve(self, method: str | None, level: str) -> tuple[Any, dict[str, Any]]:
        """The named ``method`` at knowledge ``level`` (:func:`dgse.presets.resolve`, no search)
        and its estimator's keyword arguments: the method's, overridden by these options."""
        from dgse.presets import resolve

        run = resolve(method, level, search=False)
        return run, {**run.estimator_options, **self.estimator_kwargs(run.estimator)}

    def estimator_kwargs(self, method: str) -> dict[str, Any]:
        """Keyword arguments of ``get_estimator(method, ...)`` from these options.

        Raises:
            InputDataError: a shortcut option given to an estimator that does not take it
                (the message names the options it takes), or ``-K``/``-T`` below 1.
        """
        from dgse.estimators.registry import ESTIMATORS, estimator_names

        dtype = None if self.dtype is None else Dtype(self.dtype).value
        given = {"--model": ("model", self.model), "-K": ("K", self.k), "-T": ("T", self.t),
                 "--device": ("device", self.device), "--dtype": ("dtype", dtype)}  # fmt: skip
        for name, v in (("-K", self.k), ("-T", self.t)):
            if v is not None and v < 1:
                raise InputDataError(f"{name} must be at least 1, got {v}")
        kwargs: dict[str, Any] = {}
        for flag, (key, v) in given.items():
            if v is None:
                continue
            if method in estimator_names() and not ESTIMATORS.accepts(method, key):
                raise InputDataError(
                    f"{flag} does not apply to {method} (it takes no {key!r}); "
                    f"give {method}'s options as --param KEY=VALUE"
                )
            kwargs[key] = v
        kwargs.update(parse_params(self.params))
        return kwargs

    def set_threads(self) -> None:
        """``torch.set_num_threads(threads)`` when given (PyTorch is imported only then)."""
        if self.threads is None:
            return
        if self.threads < 1:
            raise InputDataError(f"--threads must be at least 1, got {self.threads}")
        import torch

        torch.set_num_threads(self.threads)


def _fmt(v: Any, digits: int = 3) -> str:
    if v is None:
        return "-"
    if isinstance(v, float):
        if not math.isfinite(v) or abs(v) < 10**digits:
            return f"{v:.{digits}g}"
        return f"{v:.3g}" if abs(v) >= 1e7 else f"{v:.0f}"
    return str(v)


def _check_figure_path(path: Path) -> None:
    """Raise :class:`InputDataError` unless matplotlib can write a figure with ``path``'s suffix."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    supported = FigureCanvasAgg(Figure()).get_supported_filetypes()
    if path.suffix.lstrip(".").lower() not in supported:
        raise InputDataError(
            f"cannot write a figure as {path.name!r}: use one of "
            + ", ".join(f".{k}" for k in sorted(supported))
        )


def _save_figure(fig: Any, path: Path, dpi: int = 120) -> Path:
    _check_figure_path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=dpi)
    return path


# -- estimate -----------------------------------------------------------------------------------
@user_errors
@option_bundle("estimator", EstimatorOptions)
def estimate_cmd(
    case_file: Annotated[Path, typer.Argument(metavar="CASE", help="A case file (.npz).")],
    observations: Annotated[
        int, typer.Option("--observations", "-n", help="Number of sensors at random free cells.")
    ],
    out: Annotated[Path, typer.Option("--out", "-o", help="Estimate file (.npz) to write.")],
    seed: SeedOption = 0,
    method: MethodOption = None,
    estimator: EstimatorOptions = EstimatorOptions(),
    plot: Annotated[Path | None, typer.Option("--plot", help="Also save a figure of the belief.")] = None,
    knowledge: KnowledgeOption = DEFAULT_LEVEL,
) -> None:
    """Estimate the source (and fields) of a case from random noisy observations.

    Draws --observations sensors at random free cells with Table I noise (the
    observations of trial 0 of `dgse evaluate CASE --seed S`), runs the
    estimator, scores it against the case and writes the belief, the
    observations and the metrics into the output .npz.
    """
    from dgse.estimators.registry import get_estimator
    from dgse.evaluation.evaluate import estimate_once, save_estimate
    from dgse.world.case import Case

    level = check_level(knowledge)
    run, kwargs = estimator.resolve(method, level)
    method = run.method
    estimator.set_threads()
    check_output_file(out, "estimate file")
    if plot is not None:
        _check_figure_path(plot)
        check_output_file(plot, "figure")
    case = Case.load(case_file)
    case_id = case_file.stem
    with console.status(f"loading {escape(method)} ..."):
        est: Any = get_estimator(run.estimator, knowledge=Knowledge.from_case(case, level), **kwargs)
    result = estimate_once(est, case, case_id, observations, seed, reseed="seed" not in kwargs)
    obs, belief, metrics, seconds = result.observations, result.belief, result.metrics, result.seconds
    extra = {
        "case": str(case_file),
        "case_id": case_id,
        "method": method,
        "knowledge": level,
        "seed": seed,
        "n_obs": observations,
        "seconds": seconds,
        "true_source_xy": [float(case.source[0]), float(case.source[1])],
        "estimator_kwargs": kwargs,
    }
    path = save_estimate(out, belief, obs, metrics, extra)

    m = metrics.to_dict()
    x, y = belief.source_estimate()
    sx, sy = float(case.source[0]), float(case.source[1])
    mx, my = case.grid.center_of(*belief.most_likely_cell())
    table = Table.grid(padding=(0, 2))
    table.add_column(style="bold")
    table.add_column()
    table.add_row("case", f"{escape(case.name)} ({case.grid.width} x {case.grid.height} cells)")
    table.add_row(
        "method", f"{escape(method)} (knowledge: {level}), {observations} observations, seed {seed}"
    )
    table.add_row(
        "source estimate", f"({x:.2f}, {y:.2f}) m (the posterior mean); most likely at ({mx:.2f}, {my:.2f}) m"
    )
    table.add_row("true source", f"({sx:.2f}, {sy:.2f}) m")
    table.add_row(
        "error", f"[bold]{m['sl_error_m']:.2f} m[/] (most likely position {m['map_error_m']:.2f} m)"
    )
    table.add_row(
        "entropy",
        f"{m['entropy']:.2f} nats ({m['normalized_entropy']:.2f} of log N); "
        f"cross-entropy at the true cell {m['ce']:.2f} nats",
    )
    if belief.wind_mean is not None:
        table.add_row("wind", f"RMSE {_fmt(m['wf_rmse'])} m/s, NLL {_fmt(m['wf_nll'])}")
    if belief.log_conc_mean is not None:
        table.add_row(
            "concentration",
            f"log(1+c) RMSE {_fmt(m['cf_rmse'])}, NLL {_fmt(m['cf_nll'])}; RMSE {_fmt(m['cf_rmse_ppm'])} ppm",
        )
    table.add_row("time", f"{seconds:.3f} s per estimate")
    console.print(table)
    console.print(f"wrote estimate [cyan]{path_text(path)}[/]")
    if plot is not None:
        from dgse.viz.belief import plot_belief

        fig = plot_belief(belief, case, obs)
        console.print(f"wrote figure [cyan]{path_text(_save_figure(fig, plot))}[/]")


# -- evaluate -----------------------------------------------------------------------------------
def _split_positionals(args: Sequence[str], observations: Sequence[str]) -> tuple[Path, list[int]]:
    """The cases path and the observation counts from the positionals and ``--observations``.

    ``--observations 50 100 150`` reaches the command as ``--observations 50`` plus
    the positionals ``100 150``: integer positionals that are not existing paths are
    more counts; counts may also be comma-separated (``50,100``).
    """
    counts: list[int] = []
    paths: list[str] = []

    def ints(token: str) -> list[int] | None:
        parts = [p for p in token.split(",") if p.strip()]
        try:
            return [int(p) for p in parts] if parts else None
        except ValueError:
            return None

    for token in observations:
        got = ints(token)
        if got is None:
            raise InputDataError(f"--observations takes integers, got {token!r}")
        counts += got
    for token in args:
        got = ints(token)
        if got is not None and not Path(token).exists():
            counts += got
        else:
            paths.append(token)
    if len(paths) != 1:
        raise InputDataError(
            "give one CASES_DIR_OR_STORE (a directory of case files, a case file or a dataset store)"
            + (f"; got {', '.join(map(repr, paths))}" if paths else "")
        )
    if not counts:
        raise InputDataError("give the numbers of observations: --observations N [N ...]")
    return Path(paths[0]), counts


def _mean_std(agg: dict[str, Any], key: str) -> str:
    mean, std = agg.get(f"{key}_mean"), agg.get(f"{key}_std")
    if mean is None:
        return "-"
    return f"{_fmt(mean)} ± {_fmt(std, 2)}" if std is not None else _fmt(mean)


#: Rows of the aggregate table: label, metric key, statistic ("mean ± std", "median").
_TABLE_ROWS = (
    ("SL error [m]", "sl_error_m", "mean"),
    ("SL error median [m]", "sl_error_m", "median"),
    ("CE at the true cell [nats]", "ce", "mean"),
    ("WF RMSE [m/s]", "wf_rmse", "mean"),
    ("WF NLL [nats]", "wf_nll", "mean"),
    ("CF RMSE [log(1+ppm)]", "cf_rmse", "mean"),
    ("CF NLL [nats]", "cf_nll", "mean"),
    ("CF RMSE [ppm]", "cf_rmse_ppm", "mean"),
    ("CF NLL, ppm space [nats]", "cf_nll_ppm", "mean"),
    ("time per estimate, median [s]", "seconds_per_estimate", "median"),
)


def _aggregate_table(result: dict[str, Any]) -> Table:
    """Metrics as rows (mean ± std unless noted), one column per observation count."""
    split = f", split {result['split']}" if result.get("split") else ""
    table = Table(
        title=f"{escape(result['method'])} on {result['n_cases']} cases{escape(split)}, "
        f"{result['trials']} trials, seed {result['seed']}",
        title_justify="left",
        box=box.SIMPLE_HEAD,
    )
    table.add_column("metric", overflow="fold")  # a narrow terminal wraps and folds, never cuts
    aggs = result["aggregate"]
    for n in aggs:
        table.add_column(f"n = {n}", justify="right", overflow="fold")
    table.add_row("estimates", *(str(a["n_estimates"]) for a in aggs.values()))
    for label, key, stat in _TABLE_ROWS:
        cells = [_mean_std(a, key) if stat == "mean" else _fmt(a.get(f"{key}_{stat}")) for a in aggs.values()]
        table.add_row(escape(label), *cells)
    return table


@user_errors
@option_bundle("estimator", EstimatorOptions)
def evaluate_cmd(
    ctx: typer.Context,
    args: Annotated[
        list[str],
        typer.Argument(
            metavar="CASES_DIR_OR_STORE",
            help="A directory of case files, a case file or a dataset store (.h5).",
            show_default=False,
        ),
    ],
    observations: Annotated[
        list[str],
        typer.Option(
            "--observations",
            "-n",
            metavar="N [N ...]",
            help="Numbers of sensors, e.g. --observations 50 100 150 (or 50,100,150).",
            show_default=False,
        ),
    ],
    method: MethodOption = None,
    trials: Annotated[
        int, typer.Option("--trials", "-r", help="Random sensor configurations per case and count.")
    ] = 20,
    seed: SeedOption = 0,
    out: Annotated[
        Path | None, journal_output("The full result", "dgse-out/evaluate-<method>.json", "estimates")
    ] = None,
    restart: Annotated[bool, restart_option("estimates")] = False,
    split: Annotated[str, typer.Option("--split", help="Split of a dataset store.")] = "test",
    estimator: EstimatorOptions = EstimatorOptions(),
    limit: Annotated[int | None, typer.Option("--limit", help="Only the first N cases.")] = None,
    progress: ProgressOption = True,
    knowledge: KnowledgeOption = DEFAULT_LEVEL,
) -> None:
    """Evaluate an estimator on cases from random noisy observations (paper Sec. V).

    For every case, observation count and trial: sensors at random free cells
    with Table I noise, seeded by (seed, case, count, trial) so that every
    method sees the same observations; source-localization error, cross-entropy,
    wind and concentration RMSE/NLL; time per estimate.

    Every finished estimate is kept at once (in the journal beside the JSON
    file); after Ctrl-C or a kill, the same command resumes where it stopped.
    """
    from dgse.cli.common import default_output, interruptible, kept_note, resume_command, resume_note
    from dgse.evaluation.evaluate import evaluate, write_json
    from dgse.journal import count_records, journal_path

    level = check_level(knowledge)
    cases, counts = _split_positionals(args, observations)
    run, kwargs = estimator.resolve(method, level)
    method = run.method
    names = (method,) if level == DEFAULT_LEVEL else (method, level)
    out = out if out is not None else default_output("evaluate", *names)
    journal = journal_path(out)
    check_output_file(out, "JSON file")
    check_output_file(journal, "journal")
    estimator.set_threads()

    def started(kept: int, total: int) -> None:
        console.print(kept_note(journal, "estimate", kept))

    def kept() -> str:
        return resume_note(count_records(journal), "estimate", journal, resume_command(ctx))

    with interruptible(kept):
        result = evaluate(
            cases,
            run.estimator,
            counts,
            trials=trials,
            seed=seed,
            estimator_kwargs=kwargs,
            progress=progress,
            split=split,
            limit=limit,
            journal=journal,
            restart=restart,
            knowledge=level,
            on_start=started,
        )
    console.print(_aggregate_table(result))
    console.print(f"{len(result['per_case'])} estimates in {result['seconds_total']:.1f} s")
    console.print(f"wrote [cyan]{path_text(write_json(result, out))}[/]")


# -- export-onnx --------------------------------------------------------------------------------
@user_errors
def export_onnx_cmd(
    model: Annotated[
        str, typer.Option("--model", help="A .safetensors checkpoint, or 'default' (the shipped DGSE-S).")
    ],
    out: Annotated[Path, typer.Option("--out", "-o", help="ONNX file to write.")],
    variant: Annotated[
        str,
        typer.Option(
            "--variant",
            help="auto/pipeline: one graph (DGSE-S: K,T-marginalized, noise as inputs); "
            "stages: DGSE-S as three graphs (wind, conc, source).",
        ),
    ] = "auto",
    opset: Annotated[int, typer.Option("--opset", help="ONNX opset (>= 17).")] = 17,
    check: Annotated[
        bool, typer.Option("--check/--no-check", help="Compare with PyTorch on ONNX Runtime.")
    ] = True,
) -> None:
    """Export a DGSE network to ONNX for TensorRT / ONNX Runtime (dynamic batch, canvas, K, T)."""
    from dgse.models.checkpoint import load_model
    from dgse.models.onnx_export import check_onnx, export_onnx

    check_output_file(out, "ONNX file")
    if model == "default":
        from dgse.estimators.dgse import default_model_path

        path = default_model_path("dgse-s")
    else:
        path = Path(model)
    net = load_model(path)
    with console.status(f"exporting {escape(net.config.variant)} ..."):
        result = export_onnx(net, out, variant=variant, opset=opset)
    for p, stage, ins, outs in zip(result.paths, result.stages, result.inputs, result.outputs, strict=True):
        size = p.stat().st_size / 1e6
        console.print(
            f"wrote [cyan]{path_text(p)}[/] ({size:.1f} MB, {escape(stage)}): "
            f"inputs {escape(', '.join(ins))} -> outputs {escape(', '.join(outs))}"
        )
    console.print(
        f"{escape(result.dgse_variant)} {escape(result.export_variant)}, opset {result.opset}; dynamic axes: "
        "batch, height, width"
        + (", K, T (the noise inputs' leading sizes)" if "eps_wind" in result.inputs[0] else "")
    )
    if check:
        with console.status("checking with ONNX Runtime ..."):
            diff = check_onnx(net, result)
        if not diff <= 1e-3:
            raise InputDataError(f"ONNX Runtime and PyTorch disagree: max abs difference {diff:.3g}")
        console.print(f"ONNX Runtime vs PyTorch: max abs difference {diff:.2g}")


def register(app: typer.Typer) -> None:
    """Attach ``estimate``, ``evaluate`` and ``export-onnx`` to ``app`` at the top level."""
    app.command("estimate")(estimate_cmd)
    app.command("evaluate")(evaluate_cmd)
    app.command("export-onnx")(export_onnx_cmd)
