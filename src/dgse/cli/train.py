"""The ``dgse train`` command: train a DGSE network on a dataset store.

:func:`register` adds the command to a typer app.  The settings are, in
increasing priority: the paper's defaults (:class:`~dgse.training.config.TrainConfig`),
a YAML file (``--config``, e.g. ``configs/train/paper.yaml``), ``--set
KEY=VALUE`` overrides (values in YAML syntax; ``model_overrides.<key>`` and
``loss_weights.<key>`` reach the nested settings), and the dedicated options
(``--network``, ``--data``, ``--epochs``, ...).  An error names what caused
it: the YAML file, the ``--set`` item or the option (``--batch-size 0``).

Errors a user can cause end the command as in every ``dgse`` command
(:mod:`dgse.cli.common`).
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Any

import typer
from rich.markup import escape

from dgse.cli.common import (
    EXIT_INTERRUPTED,
    NOTHING_KEPT,
    ThreadsOption,
    check_output_dir,
    check_output_file,
    console,
    interruptible,
    path_text,
    print_interrupted,
    resume_command,
)
from dgse.cli.common import user_errors as _user_errors
from dgse.errors import InputDataError

__all__ = ["parse_devices", "parse_set", "register", "train_cmd"]


def parse_devices(text: str) -> int | str | list[int]:
    """``--devices``: ``"auto"``, a count (``"2"``, ``"-1"`` for all) or indices ``"0,1"``."""
    t = text.strip()
    if "," in t:
        try:
            return [int(x) for x in t.split(",") if x.strip()]
        except ValueError:
            raise InputDataError(f"--devices: bad device list {text!r}") from None
    try:
        return int(t)
    except ValueError:
        return t


def parse_set(items: list[str]) -> dict[str, Any]:
    """``--set KEY=VALUE`` items as a dict; values are parsed as YAML scalars (``3``, ``true``, ``null``)."""
    import yaml  # here, not at the top: every command imports this module

    out: dict[str, Any] = {}
    for item in items:
        key, eq, raw = item.partition("=")
        if not eq or not key.strip():
            raise InputDataError(f"--set needs KEY=VALUE, got {item!r}")
        try:
            out[key.strip()] = yaml.safe_load(raw) if raw.strip() else None
        except yaml.YAMLError:
            out[key.strip()] = raw
    return out


#: The options that set a config key, as the command line spells them (``--set`` aside).
_OPTION_OF = {
    "model": "--network",
    "data": "--data",
    "out_dir": "--out",
    "preset": "--preset",
    "epochs": "--epochs",
    "batch_size": "--batch-size",
    "max_time": "--max-time",
    "precision": "--precision",
    "accelerator": "--accelerator",
    "devices": "--devices",
    "strategy": "--strategy",
    "num_nodes": "--num-nodes",
    "num_workers": "--workers",
    "threads": "--threads",
    "seed": "--seed",
    "export": "--export",
    "init": "--init",
}


def _kept_run(out_dir: Path, ctx: typer.Context) -> str:
    """What an interrupted run kept (its epochs in last.safetensors) and the command that resumes it."""
    from dgse.training.train import LAST_NAME, read_train_state

    last = out_dir / LAST_NAME
    try:
        n = read_train_state(last).next_epoch
    except InputDataError:
        return NOTHING_KEPT
    command = resume_command(ctx, drop=("resume",), add=("--resume",))
    return f"{n} epoch{'s' * (n != 1)} kept in {last}; resume with: {command}"


@_user_errors
def train_cmd(
    ctx: typer.Context,
    network: Annotated[
        str | None,
        typer.Option(
            "--network", "-m", help="The network to train: dgse-o, dgse-p or dgse-s (default dgse-s)."
        ),
    ] = None,
    model: Annotated[str | None, typer.Option("--model", hidden=True, help="Not an option of train.")] = None,
    data: Annotated[
        Path | None, typer.Option("--data", "-d", help="Dataset store (.h5) with train and val splits.")
    ] = None,
    config_file: Annotated[
        Path | None,
        typer.Option("--config", "-c", help="YAML training config (e.g. configs/train/paper.yaml)."),
    ] = None,
    out: Annotated[
        Path | None,
        typer.Option("--out", "-o", help="Run directory for checkpoints and logs (default: runs/dgse)."),
    ] = None,
    resume: Annotated[
        bool, typer.Option("--resume", help="Continue the run in --out from its last.safetensors.")
    ] = False,
    preset: Annotated[
        str | None, typer.Option("--preset", help="Architecture preset: paper or small.")
    ] = None,
    epochs: Annotated[int | None, typer.Option("--epochs", "-e", help="Epochs in total.")] = None,
    batch_size: Annotated[
        int | None, typer.Option("--batch-size", "-b", help="Samples per step and device.")
    ] = None,
    max_time: Annotated[
        str | None,
        typer.Option(
            "--max-time",
            help="Time budget of this call, HH:MM:SS or DD:HH:MM:SS; stops cleanly after saving.",
        ),
    ] = None,
    precision: Annotated[
        str | None, typer.Option("--precision", help="32, bf16-mixed (CPU/GPU) or 16-mixed (GPU).")
    ] = None,
    accelerator: Annotated[
        str | None, typer.Option("--accelerator", help="auto, cpu or gpu (Lightning).")
    ] = None,
    devices: Annotated[
        str | None, typer.Option("--devices", help="auto, a device count (-1: all) or indices 0,1.")
    ] = None,
    strategy: Annotated[
        str | None, typer.Option("--strategy", help="Lightning strategy: auto, ddp, ...")
    ] = None,
    num_nodes: Annotated[int | None, typer.Option("--num-nodes", help="Nodes of a multi-node run.")] = None,
    workers: Annotated[
        int | None, typer.Option("--workers", "-w", help="DataLoader worker processes per device.")
    ] = None,
    threads: ThreadsOption = None,
    seed: Annotated[int | None, typer.Option("--seed", "-s", help="Seed of the run.")] = None,
    export: Annotated[
        Path | None, typer.Option("--export", help="Also write the selected model to this .safetensors file.")
    ] = None,
    init: Annotated[
        str | None,
        typer.Option(
            "--init",
            help="Start from these weights (fine-tuning): a .safetensors model of the same "
            "architecture, or 'default' for the shipped ones.",
        ),
    ] = None,
    fast_dev_run: Annotated[
        bool,
        typer.Option(
            "--fast-dev-run", help="One epoch of 2 training and 1 validation batch, writing everything."
        ),
    ] = False,
    progress: Annotated[
        bool | None, typer.Option("--progress/--no-progress", help="Show a progress bar.")
    ] = None,
    lightning_info: Annotated[
        bool,
        typer.Option("--lightning-info", help="Show Lightning's device banners, tips and notes."),
    ] = False,
    set_: Annotated[
        list[str] | None,
        typer.Option(
            "--set",
            metavar="KEY=VALUE",
            help="Override any config key (repeatable), e.g. --set lr=1e-3 "
            "--set model_overrides.base_width=4.",
        ),
    ] = None,
) -> None:
    """Train a DGSE network (paper Sec. III, App. A) on a dataset store, resumably.

    Writes into --out: last.safetensors (weights + optimizer state, for
    --resume), best.safetensors (lowest validation source loss; a model
    checkpoint), history.csv (one row per epoch), logs/version_N/metrics.csv
    (Lightning's CSV log) and config.yaml.  The settings are checked before
    PyTorch is loaded; Ctrl-C stops after the current batch, saves, and says
    how to resume.
    """
    from dgse.training.config import load_config

    if model is not None:
        raise InputDataError(
            "dgse train has no --model: give the network to train as --network (dgse-o, dgse-p or "
            "dgse-s) and weights to start from as --init FILE"
        )
    items = list(set_ or [])
    overrides: dict[str, Any] = parse_set(items)
    origins = {item.partition("=")[0].strip(): f"--set {item}" for item in items}
    options: dict[str, Any] = {
        "model": network,
        "data": str(data) if data is not None else None,
        "out_dir": str(out) if out is not None else None,
        "preset": preset,
        "epochs": epochs,
        "batch_size": batch_size,
        "max_time": max_time,
        "precision": precision,
        "accelerator": accelerator,
        "devices": parse_devices(devices) if devices is not None else None,
        "strategy": strategy,
        "num_nodes": num_nodes,
        "num_workers": workers,
        "threads": threads,
        "seed": seed,
        "export": str(export) if export is not None else None,
        "init": init,
    }
    for key, value in options.items():
        if value is not None:
            overrides[key] = value
            origins[key] = f"{_OPTION_OF[key]} {devices if key == 'devices' else value}"
    if progress is not None:
        overrides["progress_bar"] = progress
        origins["progress_bar"] = "--progress" if progress else "--no-progress"
    if fast_dev_run:
        overrides["fast_dev_run"] = True
        origins["fast_dev_run"] = "--fast-dev-run"
    if lightning_info:
        overrides["lightning_messages"] = True
        origins["lightning_messages"] = "--lightning-info"
    config = load_config(config_file, overrides, origins=origins)
    if config.data is None:
        raise InputDataError("no dataset store: pass --data STORE (or set data in the --config file)")
    out_dir = Path(config.out_dir)
    # the checks train() makes first, before anything is printed or PyTorch is loaded
    if not Path(config.data).is_file():
        raise InputDataError(f"dataset store {config.data} not found")
    check_output_dir(out_dir, "run folder")
    check_output_file(Path(config.export) if config.export else None, "exported model")

    from lightning.pytorch.utilities import rank_zero_only

    from dgse.models.networks import build_model, count_parameters
    from dgse.training.train import prepare_out_dir, train

    state = prepare_out_dir(config, resume)
    talk = getattr(rank_zero_only, "rank", 0) == 0  # set by Lightning from the environment
    if talk:
        mc = config.model_config()
        n_params = count_parameters(build_model(mc))
        what = f"resuming at epoch {state.next_epoch}" if state is not None else "training"
        del state
        console.print(
            f"{what} [bold]{escape(config.model)}[/] (preset {escape(config.preset)}, base width "
            f"{mc.base_width}, depth {mc.depth}, {n_params / 1e6:.3f} M parameters) "
            f"on [cyan]{path_text(config.data)}[/]: "
            f"{config.epochs} epochs, batch {config.batch_size}, precision {escape(config.precision)}"
            + (", fast dev run" if config.fast_dev_run else "")
        )
        console.print(
            f"metrics -> [cyan]{path_text(out_dir / 'history.csv')}[/] and "
            f"[cyan]{path_text(out_dir / 'logs')}/version_N/metrics.csv[/]; checkpoints -> "
            f"[cyan]{path_text(out_dir / 'last.safetensors')}[/], "
            f"[cyan]{path_text(out_dir / 'best.safetensors')}[/]"
        )
    with interruptible(lambda: _kept_run(out_dir, ctx), sigterm=False):  # Lightning handles SIGTERM
        result = train(config, resume=resume)
    if result.stop_reason == "interrupted":  # the first Ctrl-C: the run stopped cleanly and saved
        if talk:
            print_interrupted(_kept_run(out_dir, ctx))
        raise typer.Exit(EXIT_INTERRUPTED)
    if not talk:
        return
    stopped = {
        "max_epochs": "all epochs done",
        "max_time": "time budget reached",
        "fast_dev_run": "fast dev run",
        "already_done": f"nothing to do: {result.epochs_done} epochs already trained",
    }[result.stop_reason]
    best = (
        f"best val/source_loss {result.best_score:.4f} at epoch {result.best_epoch}"
        if result.best_score is not None
        else "no validation"
    )
    speed = f", {result.samples_per_s:.1f} samples/s" if result.samples_per_s > 0 else ""
    console.print(
        f"{stopped}: {result.epochs_done} epoch{'s' * (result.epochs_done != 1)}, "
        f"{result.global_step} steps, {best} "
        f"({result.wall_time_s:.1f} s{speed})"
    )
    if result.metrics_csv is not None:
        console.print(
            f"wrote metrics [cyan]{path_text(result.metrics_csv)}[/] and "
            f"[cyan]{path_text(result.history_csv)}[/]"
        )
    ckpts = [result.last_path] + ([result.best_path] if result.best_path is not None else [])
    console.print("checkpoints " + ", ".join(f"[cyan]{path_text(p)}[/]" for p in ckpts))
    if result.export_path is not None:
        console.print(f"exported model [cyan]{path_text(result.export_path)}[/]")
    if result.stop_reason == "max_time":
        console.print("continue with the same command and --resume")


def register(app: typer.Typer) -> None:
    """Add ``train`` (:func:`train_cmd`) to ``app``."""
    app.command("train")(train_cmd)
