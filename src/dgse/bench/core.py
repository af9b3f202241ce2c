"""What every benchmark suite shares: scenarios, result files, figures, tables, provenance.

A suite is a function ``run(ctx: BenchContext) -> None`` registered in
:data:`dgse.bench.SUITES`.  It writes everything into ``ctx.out``
(``OUT/<suite>/``):

* raw results as JSON (:meth:`BenchContext.save_json`), e.g. the complete
  :func:`dgse.evaluation.evaluate` result of every method;
* sections of the report (:meth:`BenchContext.section`), each with text,
  figures (PNG, :meth:`Section.figure`) and tables (CSV, :meth:`Section.table`);
* ``suite.json`` (:meth:`BenchContext.finish`): the manifest the HTML report
  (:mod:`dgse.bench.report`) reads: title, sections with their figure and
  table files, the command line, versions, hardware, wall time.

Scenarios (:meth:`BenchContext.scenarios`) are case files in
``OUT/_scenarios/<kind>/`` shared by all suites of one output directory:

* ``test``: with a dataset store (``--data``), one case (its first source) of
  each of the first test-split layouts in id order; without one, random
  training-distribution layouts solved with the built-in solver, one source
  each (seeded by the run's seed);
* ``ood``: out-of-domain layouts (:func:`dgse.world.generate.random_ood_layout`,
  paper App. D) solved with the built-in solver; layouts whose flow does not
  converge are skipped (and counted);
* ``filament``: the ``test`` scenarios with ``frames`` from the filament
  model (:func:`dgse.physics.filament.make_filament_case`), at most
  ``RECOMMENDED_MAX_FILAMENTS`` filaments standing for the steady field at the start (a
  minute per scenario at most; poorly ventilated layouts would need millions).

A scenario file that exists is reused, so an interrupted run continues
where it stopped and every suite of one directory sees the same scenarios.
"""

from __future__ import annotations

import csv
import datetime as _dt
import json
import math
import os
import platform
import sys
import time
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from importlib.metadata import PackageNotFoundError
from importlib.metadata import version as _pkg_version
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from dgse.errors import ConvergenceError, InputDataError
from dgse.files import (
    atomic_open,
    atomic_path,
    is_temporary,
    update_json,
    write_bytes,
    write_json,
    write_text,
)
from dgse.world.case import Case

if TYPE_CHECKING:
    from matplotlib.figure import Figure

__all__ = [
    "MANIFEST",
    "BenchContext",
    "Section",
    "cpu_model",
    "environment_info",
    "jsonable",
]

#: The manifest file of a suite's directory.
MANIFEST = "suite.json"
#: Seconds each cached result took to compute (so resumed runs still report their cost).
TIMINGS = "_timings.json"
#: Format tag of the manifest.
MANIFEST_FORMAT = "dgse-bench-suite"


def jsonable(obj: Any) -> Any:
    """``obj`` with numpy scalars/arrays as Python values and non-finite floats as None."""
    if isinstance(obj, Mapping):
        return {str(k): jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return jsonable(obj.tolist())
    if isinstance(obj, np.generic):
        return jsonable(obj.item())
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    if isinstance(obj, Path):
        return str(obj)
    return obj


def _version(dist: str) -> str | None:
    try:
        return _pkg_version(dist)
    except PackageNotFoundError:
        return None


def cpu_model() -> str:
    """The CPU's model name (``/proc/cpuinfo``), else what :mod:`platform` knows."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def environment_info() -> dict[str, Any]:
    """Versions and hardware of this run (what the report prints under every suite)."""
    info: dict[str, Any] = {
        "python": platform.python_version(),
        "platform": platform.platform(),
        "versions": {
            d: _version(d) for d in ("dgse", "numpy", "scipy", "torch", "numba", "lightning", "matplotlib")
        },
        "cpu": cpu_model(),
        "cpu_count": os.cpu_count(),
        "gpu": None,
    }
    if "torch" in sys.modules:
        import torch

        info["torch_threads"] = torch.get_num_threads()
        if torch.cuda.is_available():
            info["gpu"] = torch.cuda.get_device_name(0)
    return info


def _now() -> str:
    return _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds")


def _check_name(name: str) -> str:
    if not name or any(c in name for c in "/\\") or name.startswith("."):
        raise InputDataError(f"bad result file name {name!r}")
    return name


@dataclass
class Section:
    """One part of a suite's report: a heading, text, figures and tables.

    Create it with :meth:`BenchContext.section`; its files go into the
    suite's directory.
    """

    title: str
    text: str = ""
    figures: list[dict[str, str]] = field(default_factory=list)
    tables: list[dict[str, Any]] = field(default_factory=list)
    _dir: Path = field(default=Path("."), repr=False)

    def figure(self, fig: Figure, name: str, caption: str) -> Path:
        """Save ``fig`` as ``<name>.png`` (closing it) and list it in this section."""
        import matplotlib.pyplot as plt

        path = self._dir / f"{_check_name(name)}.png"
        with atomic_path(path) as tmp:
            fig.savefig(tmp, dpi=110, bbox_inches="tight")
        plt.close(fig)
        self.figures.append({"file": path.name, "caption": caption})
        return path

    def table(
        self,
        name: str,
        rows: Sequence[Mapping[str, Any]],
        caption: str,
        columns: Sequence[str] | None = None,
    ) -> Path:
        """Write ``rows`` as ``<name>.csv`` and list them (with ``columns`` in order) in this section."""
        cols = list(columns) if columns is not None else list(dict.fromkeys(k for r in rows for k in r))
        path = self._dir / f"{_check_name(name)}.csv"
        with atomic_open(path, "w", newline="") as f:
            w = csv.writer(f)
            w.writerow(cols)
            for r in rows:
                w.writerow(["" if r.get(c) is None else r.get(c) for c in cols])
        self.tables.append(
            {
                "file": path.name,
                "caption": caption,
                "columns": cols,
                "rows": jsonable([[r.get(c) for c in cols] for r in rows]),
            }
        )
        return path

    def to_dict(self) -> dict[str, Any]:
        return {"title": self.title, "text": self.text, "figures": self.figures, "tables": self.tables}


class BenchContext:
    """The state of one suite run: where results go, which scenarios, how big.

    Args:
        suite: the suite's name (``variants``, ``gdm``, ...).
        out_root: the run's output directory (the suite writes into ``out_root/suite``, or
            ``out_root/suite-LEVEL`` at a knowledge level other than ``map``).
        quick: a small run (CI); suites pick smaller counts with :meth:`pick`.
        data: a dataset store whose test split gives the ``test`` scenarios (None:
            random layouts solved here).
        seed: the run's seed (scenarios, observations, episodes).
        knowledge: what every method is told about each scenario besides its
            readings (:mod:`dgse.belief.knowledge`); methods that do not work
            at this level are left out and named (:meth:`methods_at_level`).
        progress: show progress bars.
        command: the command line recorded in the manifest.
    """

    def __init__(
        self,
        suite: str,
        out_root: str | os.PathLike[str],
        *,
        quick: bool = False,
        data: str | os.PathLike[str] | None = None,
        seed: int = 0,
        knowledge: str = "map",
        progress: bool = False,
        command: str | None = None,
        title: str = "",
        description: str = "",
    ) -> None:
        from dgse.belief.knowledge import check_level

        self.suite = suite
        self.root = Path(out_root)
        self.knowledge = check_level(knowledge)
        # one directory per suite and level: runs at several levels share a root (and its
        # scenarios) and appear side by side in one report
        self.out = self.root / (suite if self.knowledge == "map" else f"{suite}-{self.knowledge}")
        self.out.mkdir(parents=True, exist_ok=True)
        self.quick = bool(quick)
        self.data = Path(data) if data is not None else None
        if self.data is not None and not self.data.is_file():
            raise InputDataError(f"{self.data}: no such dataset store")
        self.seed = int(seed)
        self.progress = bool(progress)
        self.command = command if command is not None else " ".join(["dgse", *sys.argv[1:]])
        self.title = title or suite
        self.description = description
        self.sections: list[Section] = []
        self.notes: list[str] = []
        self.reused: list[str] = []  # results an earlier run wrote (cached(), evaluate_cached())
        self.started = _now()
        self._t0 = time.perf_counter()
        self.data_info: dict[str, Any] = {}

    # -- sizes -------------------------------------------------------------------------
    def pick(self, full: Any, quick: Any) -> Any:
        """``quick`` in a quick run, else ``full``."""
        return quick if self.quick else full

    # -- results -----------------------------------------------------------------------
    def section(self, title: str, text: str = "") -> Section:
        """A new report section (in order of creation)."""
        s = Section(title=title, text=text, _dir=self.out)
        self.sections.append(s)
        return s

    def save_json(self, name: str, data: Any) -> Path:
        """Write ``data`` as ``<name>.json`` in the suite's directory (atomically)."""
        return write_json(self.out / f"{_check_name(name)}.json", jsonable(data), indent=1)

    def load_json(self, name: str) -> Any | None:
        """A result written by :meth:`save_json` in an earlier (interrupted) run, or None."""
        path = self.out / f"{_check_name(name)}.json"
        if not path.is_file():
            return None
        try:
            return json.loads(path.read_text())
        except (OSError, json.JSONDecodeError):
            return None

    def cached(self, name: str, compute: Callable[[], Any]) -> Any:
        """The JSON result ``name`` if an earlier run of this directory wrote it, else ``compute()`` saved."""
        got = self.load_json(name)
        if got is not None:
            self.mark_reused(name, got)
            return got
        t0 = time.perf_counter()
        result = compute()
        self.save_json(name, result)
        self._record_seconds(name, time.perf_counter() - t0)
        return jsonable(result)

    def mark_reused(self, name: str, result: Any) -> None:
        """Note that result ``name`` came from an earlier run (with its date, when it has one)."""
        created = result.get("created") if isinstance(result, dict) else None
        self.reused.append(f"{name} of {str(created)[:10]}" if created else name)

    def _record_seconds(self, name: str, seconds: float) -> None:
        # under a lock: two runs into one directory may record times at once
        update_json(self.out / TIMINGS, lambda t: {**t, name: round(float(seconds), 2)}, default={}, indent=1)

    def add_seconds(self, name: str, seconds: float) -> None:
        """Add ``seconds`` to the compute time of result ``name``: for results kept piece by piece
        (journaled episodes), whose cost a resumed run adds to."""
        update_json(
            self.out / TIMINGS,
            lambda t: {**t, name: round(float(t.get(name, 0.0)) + float(seconds), 2)},
            default={},
            indent=1,
        )

    def compute_seconds(self) -> float:
        """Seconds spent computing this suite's results, over all (resumed) runs.

        The times :meth:`cached` recorded, plus ``seconds_total`` of result files it
        did not time (e.g. :func:`dgse.evaluation.evaluate` results saved directly).
        Work outside those pieces (figures, tables) counts only in ``wall_seconds``.
        """
        path = self.out / TIMINGS
        timings = json.loads(path.read_text()) if path.is_file() else {}
        total = sum(float(v) for v in timings.values())
        for f in self.out.glob("*.json"):
            if f.stem in timings or f.name in (MANIFEST, TIMINGS) or is_temporary(f):
                continue
            try:
                v = json.loads(f.read_text())
            except (OSError, json.JSONDecodeError):
                continue
            if isinstance(v, dict) and isinstance(v.get("seconds_total"), (int, float)):
                total += float(v["seconds_total"])
        return round(total, 2)

    def note(self, text: str) -> None:
        """A remark for the report (e.g. skipped scenarios)."""
        self.notes.append(text)

    def methods_at_level(self, methods: Sequence[str]) -> tuple[list[str], dict[str, str]]:
        """``(kept, left_out)``: the estimators of ``methods`` that work at :attr:`knowledge`, and
        for each one left out why (the levels it needs); a note records the left-out ones."""
        from dgse.estimators.registry import get_estimator

        kept: list[str] = []
        left: dict[str, str] = {}
        for m in methods:
            levels = tuple(get_estimator(m).knowledge_levels)
            if self.knowledge in levels:
                kept.append(m)
            else:
                left[m] = f"works at knowledge level {' or '.join(levels)}, not {self.knowledge}"
        if left:
            self.note(
                f"knowledge {self.knowledge!r}: left out "
                + "; ".join(f"{m} ({why})" for m, why in left.items())
            )
        return kept, left

    def finish(self) -> Path:
        """Write the manifest ``suite.json`` and return its path.

        When results of an earlier run were reused, a note says which, so that
        the wall time is not read as the cost of the whole suite.
        """
        if self.reused:
            self.note(
                f"{len(self.reused)} result(s) were reused from an earlier run in this directory "
                f"({', '.join(self.reused)}); the wall time covers this run only."
            )
        manifest = {
            "format": MANIFEST_FORMAT,
            "format_version": 1,
            "suite": self.suite,
            "title": self.title if self.knowledge == "map" else f"{self.title} (knowledge: {self.knowledge})",
            "description": self.description,
            "quick": self.quick,
            "seed": self.seed,
            "knowledge": self.knowledge,
            "command": self.command,
            "data": self.data_info or ({"store": str(self.data)} if self.data else {"store": None}),
            "started": self.started,
            "finished": _now(),
            "wall_seconds": round(time.perf_counter() - self._t0, 2),
            "compute_seconds": self.compute_seconds(),
            "environment": environment_info(),
            "notes": self.notes,
            "sections": [s.to_dict() for s in self.sections],
        }
        return write_json(self.out / MANIFEST, jsonable(manifest), indent=1)

    # -- scenarios -----------------------------------------------------------------------
    def scenario_dir(self, kind: str) -> Path:
        d = self.root / "_scenarios" / kind
        d.mkdir(parents=True, exist_ok=True)
        return d

    def scenarios(self, n: int, kind: str = "test") -> Path:
        """A directory holding (at least) ``n`` scenario case files of ``kind`` (see module doc).

        Returns the directory of exactly the first ``n`` (sorted by name): the
        suites pass it to :func:`dgse.evaluation.evaluate` and the search runner.
        """
        if n < 1:
            raise InputDataError(f"need at least one scenario, got {n}")
        if kind == "test":
            files = self._test_scenarios(n)
        elif kind == "ood":
            files = self._ood_scenarios(n)
        elif kind == "filament":
            files = self._filament_scenarios(n)
        else:
            raise InputDataError(f"unknown scenario kind {kind!r} (test, ood, filament)")
        sel = self.root / "_scenarios" / f"{kind}-{len(files)}"
        sel.mkdir(parents=True, exist_ok=True)
        for f in files:
            link = sel / f.name
            if not link.exists():
                try:
                    link.symlink_to(os.path.relpath(f, sel))
                except OSError:
                    write_bytes(link, f.read_bytes())
        return sel

    def _test_scenarios(self, n: int) -> list[Path]:
        d = self.scenario_dir("test")
        if self.data is not None:
            from dgse.data.store import DatasetStore

            with DatasetStore(self.data, mode="r") as store:
                ids = sorted(store.layouts(split="test"))
                if len(ids) < n:
                    raise InputDataError(f"{self.data}: only {len(ids)} test layouts, need {n}")
                self.data_info = {"store": str(self.data), "split": "test", "layouts": ids[:n]}
                out = []
                for lid in ids[:n]:
                    path = d / f"{lid}_src0.npz"
                    if not path.is_file():
                        store.case(lid, 0).save(path)
                    out.append(path)
                return out
        from dgse.physics.scenario import random_cases

        self.data_info = {"store": None, "generated": "random training-distribution layouts, built-in solver"}
        out = []
        i = 0
        ss = np.random.SeedSequence([self.seed, 7001])
        seeds = ss.spawn(10 * n + 10)
        while len(out) < n and i < len(seeds):
            path = d / f"gen{i:03d}.npz"
            if not path.is_file():
                try:
                    random_cases(np.random.default_rng(seeds[i]), n_sources=1)[0].save(path)
                except ConvergenceError:
                    i += 1
                    continue
            out.append(path)
            i += 1
        return out

    def _ood_scenarios(self, n: int) -> list[Path]:
        from dgse.physics.scenario import solve_cases
        from dgse.world.generate import random_inlet_velocity, random_ood_layout, random_sources

        d = self.scenario_dir("ood")
        seeds = np.random.SeedSequence([self.seed, 7002]).spawn(4 * n + 4)
        out, failed = [], 0
        for i, s in enumerate(seeds):
            if len(out) >= n:
                break
            path = d / f"ood{i:03d}.npz"
            skip = d / f"ood{i:03d}.failed"
            if skip.exists():
                continue
            if not path.is_file():
                rng = np.random.default_rng(s)
                layout = random_ood_layout(rng, name=f"ood{i:03d}")
                v = random_inlet_velocity(rng)
                src = random_sources(layout, rng, n=1)
                try:
                    solve_cases(layout, v, src, "builtin")[0].save(path)
                except ConvergenceError as e:
                    write_text(skip, str(e))
                    failed += 1
                    continue
            out.append(path)
        if failed:
            self.note(f"{failed} out-of-domain layout(s) skipped: the built-in solver did not converge")
        return out

    def _filament_scenarios(self, n: int) -> list[Path]:
        from dgse.physics.filament import RECOMMENDED_MAX_FILAMENTS, FilamentSettings, make_filament_case

        d = self.scenario_dir("filament")
        out = []
        settings = FilamentSettings(duration=self.pick(240.0, 60.0), max_filaments=RECOMMENDED_MAX_FILAMENTS)
        for i, src in enumerate(self._test_scenarios(n)):
            path = d / src.name
            if not path.is_file():
                case = Case.load(src)
                make_filament_case(case, settings, seed=self.seed * 1000 + i).save(path)
            out.append(path)
        return out


def load_manifests(root: str | os.PathLike[str]) -> list[dict[str, Any]]:
    """The manifests of every suite under ``root`` (sorted by suite name)."""
    out = []
    for p in sorted(Path(root).glob(f"*/{MANIFEST}")):
        m = json.loads(p.read_text())
        if m.get("format") == MANIFEST_FORMAT:
            m["_dir"] = str(p.parent)
            out.append(m)
    return out


def mean_std(values: Iterable[float | None]) -> tuple[float | None, float | None]:
    """Mean and population std of the finite values (None, None when there are none)."""
    v = np.array([x for x in values if x is not None and math.isfinite(x)], dtype=float)
    if v.size == 0:
        return None, None
    return float(v.mean()), float(v.std())
