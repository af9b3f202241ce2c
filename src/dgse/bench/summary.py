"""The summary of a benchmark report (``summary.md``), written from the suites' result files.

:func:`write_summary` reads the tables (CSV) and result files (JSON, the manifests) that
``dgse bench`` wrote under a results directory and writes ``DIR/summary.md``: where DGSE-S and
dgse-phys win and where they lose, and by how much.  ``dgse report`` writes it before the
HTML page, which shows it first (:func:`dgse.bench.report.write_report`), so the summary is
never typed by hand and cannot drift from its tables.

Every number of the summary is read from a file or computed from numbers read from files,
and :func:`build_summary` returns with the text the list of them (:class:`Cited`): the text
as written, the value, the files, rows and columns it came from and, for a computed one, how
it was computed.  Which way a comparison goes (who has the lower error, at which counts) is
computed too, so the wording follows the numbers.  A statement whose data is missing (a
suite not run, a table without the row) is left out: a run of a few suites, or a quick run,
gets the summary of what it holds.
"""

from __future__ import annotations

import csv
import json
import math
import os
import re
import statistics
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from dgse.bench.core import load_manifests
from dgse.files import write_text
from dgse.presets import NETWORK_METHOD, PHYSICS_METHOD

__all__ = ["SUMMARY_NAME", "Cited", "Source", "build_summary", "write_summary"]

#: The file the summary is written to inside the results directory.
SUMMARY_NAME = "summary.md"

#: Suites whose results differ per knowledge level, in the order the summary names the levels.
LEVELS = ("map", "openings", "wind")


class _Missing(Exception):
    """A file, row or column a statement needs is not in the results (the statement is left out)."""


@dataclass(frozen=True)
class Source:
    """Where a number came from: a file under the results directory, a row, a column."""

    file: str
    row: tuple[tuple[str, Any], ...] = ()
    column: str = ""


@dataclass
class Cited:
    """One number of the summary: as written, its value, its sources and how it was computed
    from them (``""``: it is the one source's value)."""

    text: str
    value: float | str
    sources: tuple[Source, ...]
    how: str = ""
    #: what the text shows of the value (100: a fraction shown as a percentage)
    scale: float = 1.0


# -- formats ---------------------------------------------------------------------------------
def _f2(x: float) -> str:
    return f"{x:.2f}"


def _f3(x: float) -> str:
    return f"{x:.3f}"


def _by_size(x: float, steps: tuple[tuple[float, str], ...], rest: str) -> str:
    """``x`` in the format of the first ``(threshold, format)`` step whose threshold ``|x|``
    reaches, else in ``rest``."""
    a = abs(x)
    for threshold, spec in steps:
        if a >= threshold:
            return format(x, spec)
    return format(x, rest)


def _sig3(x: float) -> str:
    """Three significant digits below 1000 (6.69, 13.8), thousands separators above."""
    return _by_size(x, ((1000, ",.0f"), (100, ".0f"), (10, ".1f")), ".2f")


def _sig2(x: float) -> str:
    """Two significant digits (0.33, 0.16, 1.5, 24)."""
    if x == 0:
        return "0"
    digits = max(0, 1 - math.floor(math.log10(abs(x))))
    return f"{x:.{digits}f}"


def _pct(x: float) -> str:
    """A fraction as a whole percentage (0.787 -> 79)."""
    return f"{100 * x:.0f}"


def _int(x: float) -> str:
    return f"{round(x):,}"


def _seconds(x: float) -> str:
    """Seconds: 0.086, 0.32, 2.7, 1,359."""
    return _by_size(x, ((100, ",.0f"), (1, ".1f"), (0.1, ".2f")), ".3f")


def _nominal(k: float) -> float:
    """The share of a Gaussian within ``k`` standard deviations of its mean."""
    return math.erf(k / math.sqrt(2.0))


# -- the results -----------------------------------------------------------------------------
def _parse(value: str) -> Any:
    if value == "":
        return None
    if value in ("True", "False"):
        return value == "True"
    for kind in (int, float):
        try:
            return kind(value)
        except ValueError:
            pass
    m = re.match(r"^\s*(-?\d+(?:\.\d+)?)\s*\(", value)  # "1.234 (0.567)": mean (std)
    if m:
        return float(m.group(1))
    return value


class _Row(dict):
    """A table row (values parsed) that knows its file and key."""

    file: str = ""
    key: tuple[tuple[str, Any], ...] = ()


class _Results:
    """The suites' result files under one directory, read on demand."""

    def __init__(self, root: Path) -> None:
        self.root = root
        self.manifests = {Path(m["_dir"]).name: m for m in load_manifests(root)}
        self._tables: dict[tuple[str, str], list[_Row]] = {}

    def has(self, suite: str) -> bool:
        return suite in self.manifests

    def manifest(self, suite: str) -> dict[str, Any]:
        if suite not in self.manifests:
            raise _Missing(suite)
        return self.manifests[suite]

    def rows(self, suite: str, table: str, key: Sequence[str]) -> list[_Row]:
        """Every row of ``suite/table.csv``, each keyed by its ``key`` columns."""
        if (suite, table) not in self._tables:
            self.manifest(suite)
            path = self.root / suite / f"{table}.csv"
            if not path.is_file():
                raise _Missing(f"{suite}/{table}.csv")
            out = []
            with path.open(newline="") as f:
                for raw in csv.DictReader(f):
                    row = _Row({k: _parse(v) for k, v in raw.items()})
                    row.file = f"{suite}/{table}.csv"
                    row.key = tuple((k, row.get(k)) for k in key)
                    out.append(row)
            self._tables[suite, table] = out
        return self._tables[suite, table]

    def row(self, suite: str, table: str, key: Sequence[str], **where: Any) -> _Row:
        """The one row of ``suite/table.csv`` whose columns equal ``where``."""
        got = [r for r in self.rows(suite, table, key) if all(r.get(k) == v for k, v in where.items())]
        if len(got) != 1:
            raise _Missing(f"{suite}/{table}.csv: {len(got)} rows with {where}")
        return got[0]

    def json(self, suite: str, name: str) -> Any:
        self.manifest(suite)
        path = self.root / suite / name
        if not path.is_file():
            raise _Missing(f"{suite}/{name}")
        return json.loads(path.read_text())


# -- the numbers -----------------------------------------------------------------------------
@dataclass
class _Writer:
    """Numbers into text, each recorded with its sources."""

    results: _Results
    cited: list[Cited] = field(default_factory=list)

    def cell(self, row: _Row, column: str, fmt: Callable[[float], str] = _f2) -> str:
        """The value of ``row[column]``, written with ``fmt``."""
        v = row.get(column)
        if not isinstance(v, (int, float)) or isinstance(v, bool) or not math.isfinite(v):
            raise _Missing(f"{row.file}: no number in {column} of {dict(row.key)}")
        return self.value(float(v), fmt, [(row, column)])

    def num(self, row: _Row, column: str) -> float:
        v = row.get(column)
        if not isinstance(v, (int, float)) or isinstance(v, bool) or not math.isfinite(v):
            raise _Missing(f"{row.file}: no number in {column} of {dict(row.key)}")
        return float(v)

    def value(
        self,
        value: float,
        fmt: Callable[[float], str],
        cells: Iterable[tuple[_Row, str]] = (),
        how: str = "",
        files: Iterable[str] = (),
    ) -> str:
        """``value`` written with ``fmt``, recorded with the cells (or files) it came from."""
        sources = tuple(Source(r.file, r.key, c) for r, c in cells) + tuple(Source(f) for f in files)
        text = fmt(value)
        self.cited.append(Cited(text, value, sources, how, 100.0 if fmt is _pct else 1.0))
        return text

    def text(self, value: str, file: str, how: str = "") -> str:
        """A number-bearing string read from a file as it is (a date, a map size)."""
        self.cited.append(Cited(value, value, (Source(file),), how))
        return value

    def span(
        self, cells: Sequence[tuple[_Row, str]], fmt: Callable[[float], str] = _f2, unit: str = ""
    ) -> str:
        """``lo-hi`` (or one value) of the cells, in ``fmt``."""
        values = [self.num(r, c) for r, c in cells]
        if not values:
            raise _Missing("no values")
        lo, hi = min(values), max(values)
        if fmt(lo) == fmt(hi):
            return self.value(lo, fmt, cells, "min") + unit
        return self.value(lo, fmt, cells, "min") + "-" + self.value(hi, fmt, cells, "max") + unit

    def label(self, name: str) -> str:
        from dgse.estimators.registry import ESTIMATORS

        return ESTIMATORS.label(name)


def _counts_text(counts: Sequence[int], all_counts: Sequence[int], w: _Writer, file: str) -> str:
    """``at every count``, ``from 10 to 100 readings``, ``from 100 on`` or ``at 5, 50``."""
    counts = sorted(counts)
    if list(counts) == sorted(all_counts):
        return "at every count"
    idx = [sorted(all_counts).index(c) for c in counts]
    c = [w.value(x, _int, files=[file], how="count") for x in counts]
    if idx == list(range(idx[0], idx[-1] + 1)) and len(counts) > 1:
        if idx[-1] == len(all_counts) - 1:
            return f"from {c[0]} readings on"
        return f"from {c[0]} to {c[-1]} readings"
    return "at " + " and ".join([", ".join(c[:-1]), c[-1]] if len(c) > 1 else c) + " readings"


def _seq(parts: Sequence[str]) -> str:
    return parts[0] if len(parts) == 1 else ", ".join(parts[:-1]) + " and " + parts[-1]


# -- statements ------------------------------------------------------------------------------
GSL_KEY = ("method", "scenario")


def _suite_at(suite: str, level: str) -> str:
    return suite if level == "map" else f"{suite}-{level}"


def _intro(w: _Writer) -> str:
    r = w.results
    at = {lv: [s for s in ("gsl", "calibration", "search") if r.has(_suite_at(s, lv))] for lv in LEVELS}
    suites = sorted(r.manifests)
    lines = [
        "Written by `dgse report` from the suites' result files in this directory: every number "
        "below is read from a table (CSV) or result file of the suite named beside it, each "
        "produced by the command shown under its suite in the report. Every suite compares its "
        "methods at one knowledge level (what each is told besides the readings): `map` (the "
        "paper's setting) in the suites without a suffix"
    ]
    extra = [f"`{lv}` in " + _seq([f"`{_suite_at(s, lv)}`" for s in at[lv]]) for lv in LEVELS[1:] if at[lv]]
    if extra:
        lines[0] += "; " + "; ".join(extra)
    lines[0] += "."
    needs = _needs_more_than_map(w)
    if needs:
        lines.append(
            _seq([f"`{m}`" for m in needs])
            + " need more than the map and appear only in the suites of the other levels."
        )
    # when each suite finished, newest first
    by_day: dict[str, list[str]] = {}
    for s in suites:
        day = str(r.manifests[s].get("finished") or "")[:10]
        if day:
            by_day.setdefault(day, []).append(s)
    if by_day:
        parts = [
            _seq([f"`{s}`" for s in names])
            + " finished on "
            + w.text(day, f"{names[0]}/suite.json", "finished")
            for day, names in sorted(by_day.items(), reverse=True)
        ]
        lines.append("Runs: " + "; ".join(parts) + ".")
    stores = {
        str(m["data"].get("store")): m["data"].get("split")
        for m in r.manifests.values()
        if isinstance(m.get("data"), dict) and m["data"].get("store")
    }
    if stores:
        lines.append(
            "Scenarios: "
            + _seq(
                [
                    f"the {split + ' split' if split else 'scenarios'} of `{Path(store).name}`"
                    for store, split in stores.items()
                ]
            )
            + "."
        )
    quick = [s for s in suites if r.manifests[s].get("quick")]
    if quick:
        lines.append("Quick (CI-sized) runs: " + _seq([f"`{s}`" for s in quick]) + ".")
    try:
        lines.append(_checkpoints(w))
    except _Missing:
        pass
    return " ".join(lines)


def _needs_more_than_map(w: _Writer) -> list[str]:
    """The methods of the ``gsl`` suites at other levels that the ``map`` suite left out."""
    r = w.results
    at_map = {x["method"] for x in r.rows("gsl", "gsl_only", GSL_KEY)} if r.has("gsl") else set()
    other: list[str] = []
    for lv in LEVELS[1:]:
        suite = _suite_at("gsl", lv)
        if r.has(suite) and at_map:
            other += [x["method"] for x in r.rows(suite, "gsl_only", GSL_KEY) if x["method"] not in at_map]
    return list(dict.fromkeys(other))


_CHECKPOINT = re.compile(r"(DGSE-[OPS]) epoch (\d+) \((\d+) steps\)")


def _checkpoints(w: _Writer) -> str:
    text = " ".join(s.get("text", "") for s in w.results.manifest("variants").get("sections", []))
    found = {m.group(1): int(m.group(3)) for m in _CHECKPOINT.finditer(text)}
    if not found:
        raise _Missing("checkpoints")
    order = [k for k in ("DGSE-S", "DGSE-O", "DGSE-P") if k in found]
    parts = [f"{k} {w.value(found[k], _int, files=['variants/suite.json'])}" for k in order]
    return (
        "The shipped models' checkpoints were taken after "
        + _seq(parts)
        + " optimizer steps (the `variants` suite's text; the model cards say how they were trained)."
    )


def _gdm_uncertainty(w: _Writer) -> str:
    r = w.results
    per = r.rows("gdm", "fig8_gdm_per_scenario", ("method", "scenario", "n_obs"))
    cells: dict[tuple[Any, Any], dict[str, _Row]] = {}
    for row in per:
        cells.setdefault((row["scenario"], row["n_obs"]), {})[row["method"]] = row
    comparable = [c for c in cells.values() if NETWORK_METHOD in c]
    wins = sum(
        1
        for c in comparable
        if min((m for m in c if c[m].get("nll_comparable")), key=lambda m: w.num(c[m], "cf_nll_ppm_mean"))
        == NETWORK_METHOD
    )
    nll_cells = [(c[m], "cf_nll_ppm_mean") for c in comparable for m in c if c[m].get("nll_comparable")]
    n = w.value(len(comparable), _int, nll_cells, "cells")
    k = w.value(wins, _int, nll_cells, "cells where DGSE-S's cf_nll_ppm_mean is the lowest")
    where = f"in all {n}" if wins == len(comparable) else f"in {k} of {n}"
    ppm = r.rows("gdm", "gdm_overall_ppm", ("method", "n_obs"))
    counts = sorted({row["n_obs"] for row in ppm})
    lo, hi = counts[0], counts[-1]
    s_lo = r.row("gdm", "gdm_overall_ppm", ("method", "n_obs"), method=NETWORK_METHOD, n_obs=lo)
    s_hi = r.row("gdm", "gdm_overall_ppm", ("method", "n_obs"), method=NETWORK_METHOD, n_obs=hi)
    others = sorted(
        {row["method"] for row in ppm if row["method"] != NETWORK_METHOD and row.get("nll_comparable")}
    )
    other_cells = [(row, "cf_nll_ppm_mean") for row in ppm if row["method"] in others]
    text = (
        f"**Concentration uncertainty** (`gdm`): against the mapping baselines DGSE-S has the lowest "
        f"concentration NLL (ppm) {where} scenario x count cells: "
        f"{w.cell(s_lo, 'cf_nll_ppm_mean', _sig2)} / {w.cell(s_hi, 'cf_nll_ppm_mean', _sig2)} nats at "
        f"{w.cell(s_lo, 'n_obs', _int)} / {w.cell(s_hi, 'n_obs', _int)} observations against "
        f"{w.span(other_cells, _sig2)} for {_seq([w.label(m) for m in others])}."
    )
    log = r.rows("gdm", "gdm_overall_log", ("method", "n_obs"))
    l_lo = r.row("gdm", "gdm_overall_log", ("method", "n_obs"), method=NETWORK_METHOD, n_obs=lo)
    l_hi = r.row("gdm", "gdm_overall_log", ("method", "n_obs"), method=NETWORK_METHOD, n_obs=hi)
    lowest = all(
        w.num(
            r.row("gdm", "gdm_overall_log", ("method", "n_obs"), method=NETWORK_METHOD, n_obs=c),
            "cf_rmse_mean",
        )
        <= min(w.num(x, "cf_rmse_mean") for x in log if x["n_obs"] == c)
        for c in counts
    )
    rest = [(row, "cf_rmse_mean") for row in log if row["method"] != NETWORK_METHOD]
    text += (
        f" In `log(1 + ppm)` space its RMSE is "
        f"{'also the lowest at every count' if lowest else 'not always the lowest'} "
        f"({w.cell(l_lo, 'cf_rmse_mean')} -> {w.cell(l_hi, 'cf_rmse_mean')} against {w.span(rest, _sig2)})."
    )
    return text


def _gdm_ppm_rmse(w: _Writer) -> str:
    per = w.results.rows("gdm", "fig8_gdm_per_scenario", ("method", "scenario", "n_obs"))
    cells: dict[tuple[Any, Any], dict[str, _Row]] = {}
    for row in per:
        cells.setdefault((row["scenario"], row["n_obs"]), {})[row["method"]] = row
    cells = {k: c for k, c in cells.items() if NETWORK_METHOD in c and len(c) > 1}
    all_cells = [(c[m], "cf_rmse_ppm_mean") for c in cells.values() for m in c]
    wins = sum(
        1 for c in cells.values() if min(c, key=lambda m: w.num(c[m], "cf_rmse_ppm_mean")) == NETWORK_METHOD
    )
    ratios, best = [], set()
    for c in cells.values():
        m_best = min((m for m in c if m != NETWORK_METHOD), key=lambda m: w.num(c[m], "cf_rmse_ppm_mean"))
        best.add(m_best)
        ratios.append(w.num(c[NETWORK_METHOD], "cf_rmse_ppm_mean") / w.num(c[m_best], "cf_rmse_ppm_mean"))
    n = w.value(len(cells), _int, all_cells, "cells")
    lead = (
        "DGSE-S never has the lowest"
        if wins == 0
        else f"DGSE-S has the lowest in {w.value(wins, _int, all_cells, 'cells where lowest')} of {n} cells"
    )
    ratio = w.value(statistics.median(ratios), _f2, all_cells, "median over cells of DGSE-S / best baseline")
    return (
        f"**Concentration RMSE in ppm** (`gdm`): {lead}; a median {ratio}x the best baseline "
        f"({' or '.join(w.label(m) for m in sorted(best))}), although its log-space RMSE is the lowest: "
        "the ppm error is dominated by the few high-concentration cells near the source."
    )


def _gsl_rows(w: _Writer, level: str) -> dict[str, _Row]:
    suite = _suite_at("gsl", level)
    return {
        row["method"]: row for row in w.results.rows(suite, "gsl_only", GSL_KEY) if row["scenario"] == "all"
    }


def _gsl_trials(w: _Writer, suite: str, method: str) -> str:
    rows = [
        r
        for r in w.results.rows(suite, "gsl_only", GSL_KEY)
        if r["method"] == method and r["scenario"] != "all"
    ]
    per = {w.num(r, "trials") for r in rows}
    if len(per) != 1:
        raise _Missing("trials differ")
    return w.value(per.pop(), _int, [(r, "trials") for r in rows], "trials per scenario")


def _threads(w: _Writer, suite: str) -> str:
    env = w.results.manifest(suite).get("environment") or {}
    t = env.get("torch_threads")
    if not isinstance(t, int):
        raise _Missing("threads")
    word = w.value(t, _int, files=[f"{suite}/suite.json"], how="environment.torch_threads")
    return f"{word} thread{'s' if t != 1 else ''}"


def _gsl(w: _Writer) -> str:
    r = w.results
    rows = _gsl_rows(w, "map")
    scen = sorted({x["scenario"] for x in r.rows("gsl", "gsl_only", GSL_KEY) if x["scenario"] != "all"})
    ev = r.json("gsl", f"eval_{NETWORK_METHOD}.json")
    n_obs = ev["observation_counts"]
    if len(n_obs) != 1:
        raise _Missing("one count")
    count = w.value(n_obs[0], _int, files=[f"gsl/eval_{NETWORK_METHOD}.json"], how="observation_counts")
    n_scen = w.value(len(scen), _int, files=["gsl/gsl_only.csv"], how="scenarios")
    methods = sorted(rows, key=lambda m: w.num(rows[m], "sl_error_m_mean"))
    best = methods[0]
    rest = [m for m in methods[1:]]
    parts = []
    for m in rest:
        t = ""
        if m != NETWORK_METHOD:
            trials = _gsl_trials(w, "gsl", m)
            if trials != _gsl_trials(w, "gsl", NETWORK_METHOD):
                t = f" ({trials} trials per scenario)"
        parts.append(f"{w.cell(rows[m], 'sl_error_m_mean')} m for {w.label(m)}{t}")
    text = (
        f"**Source localization from {count} random readings** (`gsl`, {n_scen} test layouts x "
        f"{_gsl_trials(w, 'gsl', NETWORK_METHOD)} trials): at `map` {w.label(best)} has the lowest "
        f"mean error, "
        f"{w.cell(rows[best], 'sl_error_m_mean')} m, against " + _seq(parts) + "."
    )
    by_ce = min(rows, key=lambda m: w.num(rows[m], "ce_mean"))
    by_med = min(rows, key=lambda m: w.num(rows[m], "sl_error_m_median"))
    if by_ce == by_med:
        others = [m for m in methods if m != by_ce]
        text += (
            f" {w.label(by_ce)} has the lowest CE ({w.cell(rows[by_ce], 'ce_mean', _sig3)} nats against "
            + ", ".join(w.cell(rows[m], "ce_mean", _sig3) for m in others)
            + f") and median error ({w.cell(rows[by_ce], 'sl_error_m_median')} against "
            + ", ".join(w.cell(rows[m], "sl_error_m_median") for m in others)
            + " m, in the order above)."
        )
    if NETWORK_METHOD in rows and PHYSICS_METHOD in rows:
        text += (
            f" DGSE-S takes {w.cell(rows[NETWORK_METHOD], 'seconds_median', _seconds)} s an estimate against "
            f"{w.label(PHYSICS_METHOD)}'s {w.cell(rows[PHYSICS_METHOD], 'seconds_median', _seconds)} s "
            f"(median, {_threads(w, 'gsl')})."
        )
    for level in LEVELS[1:]:
        try:
            text += " " + _gsl_level(w, level)
        except _Missing:
            pass
    return text


def _gsl_level(w: _Writer, level: str) -> str:
    rows = _gsl_rows(w, level)
    suite = _suite_at("gsl", level)
    phys = rows[PHYSICS_METHOD]
    oracle = [m for m, x in rows.items() if x.get("oracle")]
    named = {"openings": "With the openings known", "wind": "With the case's wind given"}[level]
    others = [m for m in ("adjoint", NETWORK_METHOD) if m in rows and not rows[m].get("oracle")]
    if level == "wind":
        others = oracle or others
    lead_err = all(
        w.num(phys, "sl_error_m_mean") < w.num(rows[m], "sl_error_m_mean")
        for m in rows
        if m != PHYSICS_METHOD
    )
    lead_ce = all(w.num(phys, "ce_mean") < w.num(rows[m], "ce_mean") for m in rows if m != PHYSICS_METHOD)
    lead = (
        "leads in error and CE"
        if lead_err and lead_ce
        else "leads in error"
        if lead_err
        else "leads in CE"
        if lead_ce
        else "does not lead"
    )
    pairs = [
        f"{w.cell(rows[m], 'sl_error_m_mean')} / {w.cell(rows[m], 'ce_mean', _sig3)} for {w.label(m)}"
        for m in others
    ]
    text = (
        f"**{named}** (`{suite}`) {w.label(PHYSICS_METHOD)} {lead}: {w.cell(phys, 'sl_error_m_mean')} m / "
        f"{w.cell(phys, 'ce_mean', _sig3)} nats against " + _seq(pairs) + "."
    )
    if oracle:
        o = rows[oracle[0]]
        below = w.num(phys, "sl_error_m_mean") < w.num(o, "sl_error_m_mean") and w.num(
            phys, "ce_mean"
        ) < w.num(o, "ce_mean")
        if below:
            text += (
                f" On these layouts {w.label(PHYSICS_METHOD)} is below the oracle (the true flow) in both."
            )
    return text


CAL_KEY = ("method", "n_obs")


def _cal(w: _Writer, level: str) -> list[_Row]:
    return w.results.rows(_suite_at("calibration", level), "calibration", CAL_KEY)


def _calibration_win(w: _Writer) -> str:
    rows = _cal(w, "map")
    s = [x for x in rows if x["method"] == NETWORK_METHOD]
    text = (
        f"**Honest uncertainty** (`calibration`): DGSE-S's source credible sets are calibrated (calibration "
        f"error {w.span([(x, 'source_cal_error') for x in s])}, median credible level of the truth "
        f"{w.span([(x, 'source_median_level') for x in s])}); its wind intervals cover "
        f"{w.span([(x, 'wind_cov_1sigma') for x in s], _pct, ' %')} (one sigma, nominal "
        f"{w.value(_nominal(1), _pct, how='Gaussian')} %) and "
        f"{w.span([(x, 'wind_cov_2sigma') for x in s], _pct, ' %')} "
        f"(two sigma, nominal {w.value(_nominal(2), _pct, how='Gaussian')} %)."
    )
    try:
        levels, errs, count = [], [], None
        for lv in LEVELS:
            p = [x for x in _cal(w, lv) if x["method"] == PHYSICS_METHOD]
            first = min(p, key=lambda x: x["n_obs"])
            count = count or first
            levels.append(f"`{lv}`")
            errs.append(w.cell(first, "source_cal_error", _f3))
        text += (
            f" {w.label(PHYSICS_METHOD)}'s source posterior is calibrated from few readings (error "
            + " / ".join(errs)
            + f" at {w.cell(count, 'n_obs', _int)} readings at "
            + " / ".join(levels)
            + ") and grows too broad with many (below); its field intervals are too wide (below)."
        )
    except _Missing:
        pass
    return text


def _calibration_conc(w: _Writer) -> str:
    s = [x for x in _cal(w, "map") if x["method"] == NETWORK_METHOD]
    cov = [w.num(x, "conc_cov_2sigma") for x in s]
    verb = "overconfident" if max(cov) < _nominal(2) else "not always overconfident"
    return (
        f"**Concentration intervals are {verb} in the tails** (`calibration`): DGSE-S's two-sigma "
        f"intervals of `log(1 + ppm)` cover {w.span([(x, 'conc_cov_2sigma') for x in s], _pct, ' %')} "
        f"(nominal {w.value(_nominal(2), _pct, how='Gaussian')} %)."
    )


def _calibration_phys(w: _Writer) -> str:
    per = {lv: [x for x in _cal(w, lv) if x["method"] == PHYSICS_METHOD] for lv in LEVELS}
    per = {lv: v for lv, v in per.items() if v}
    if not per:
        raise _Missing("dgse-phys calibration")
    suites = [f"`{_suite_at('calibration', lv)}`" for lv in per]
    w1 = [w.span([(x, "wind_cov_1sigma") for x in v], _pct, " %") + f" at `{lv}`" for lv, v in per.items()]
    w2 = [w.span([(x, "wind_cov_2sigma") for x in v], _pct, " %") for v in per.values()]
    c2 = [w.span([(x, "conc_cov_2sigma") for x in v], _pct, " %") for v in per.values()]
    allp = [x for v in per.values() for x in v]
    s = [x for x in _cal(w, "map") if x["method"] == NETWORK_METHOD]
    text = (
        f"**{w.label(PHYSICS_METHOD)}'s field uncertainty is too wide** ({', '.join(suites)}): its wind and "
        "concentration variances add a model error chosen by likelihood on validation scenarios to the "
        "spread between its flow hypotheses. On these test scenarios the one-sigma wind intervals cover "
        + _seq(w1)
        + f" (nominal {w.value(_nominal(1), _pct, how='Gaussian')} %), the two-sigma ones "
        + ", ".join(w2)
        + "; log-concentration two-sigma intervals "
        + ", ".join(c2)
        + f" (nominal {w.value(_nominal(2), _pct, how='Gaussian')} %). The errors are heavy-tailed, so one "
        "Gaussian per cell is too wide for most cells and still too narrow where a jet or plume is "
        "misplaced: the calibration error (mean gap over all levels) is "
        f"{w.span([(x, 'wind_cal_error') for x in allp])} for the wind and "
        f"{w.span([(x, 'conc_cal_error') for x in allp])} for the concentration, against DGSE-S's "
        f"{w.span([(x, 'wind_cal_error') for x in s])} and {w.span([(x, 'conc_cal_error') for x in s])}."
    )
    lasts = {lv: max(v, key=lambda x: x["n_obs"]) for lv, v in per.items()}
    s_last = max(s, key=lambda x: x["n_obs"])
    levels = [w.num(x, "source_median_level") for x in lasts.values()]
    if max(levels) < 0.5:
        text += (
            f" Its source posterior grows too broad with many readings (the gas evidence is tempered): at "
            f"{w.cell(s_last, 'n_obs', _int)} readings the truth's median credible level is "
            + " / ".join(w.cell(x, "source_median_level") for x in lasts.values())
            + " at "
            + " / ".join(f"`{lv}`" for lv in lasts)
            + " (one half when calibrated), calibration error "
            + " / ".join(w.cell(x, "source_cal_error") for x in lasts.values())
            + f" against DGSE-S's {w.cell(s_last, 'source_cal_error')}."
        )
    return text


VAR_KEY = ("method", "n_obs")


def _variants(w: _Writer) -> dict[str, dict[int, _Row]]:
    out: dict[str, dict[int, _Row]] = {}
    for row in w.results.rows("variants", "variants", VAR_KEY):
        out.setdefault(row["method"], {})[row["n_obs"]] = row
    if not {NETWORK_METHOD, "dgse-p"} <= set(out):
        raise _Missing("variants")
    return out


def _variants_fields(w: _Writer) -> str:
    v = _variants(w)
    s, p = v[NETWORK_METHOD], v["dgse-p"]
    counts = sorted(set(s) & set(p))
    mid = min(counts, key=lambda c: abs(c - 50))
    wind = [c for c in counts if w.num(s[c], "wf_rmse_mean") < w.num(p[c], "wf_rmse_mean")]
    nll = [c for c in counts if w.num(s[c], "cf_nll_mean") < w.num(p[c], "cf_nll_mean")]
    if not wind and not nll:
        raise _Missing("no field win")
    parts = []
    if wind:
        parts.append(
            f"lower wind RMSE {_counts_text(wind, counts, w, 'variants/variants.csv')} "
            f"({w.cell(s[mid], 'wf_rmse_mean')} vs {w.cell(p[mid], 'wf_rmse_mean')} m/s at "
            f"{w.cell(s[mid], 'n_obs', _int)} readings)"
        )
    if nll:
        at = mid if mid in nll else nll[0]
        parts.append(
            f"lower concentration NLL {_counts_text(nll, counts, w, 'variants/variants.csv')} "
            f"({w.cell(s[at], 'cf_nll_mean')} vs {w.cell(p[at], 'cf_nll_mean')} at "
            f"{w.cell(s[at], 'n_obs', _int)})"
        )
    return "**Fields against DGSE-P from few readings** (`variants`): DGSE-S has " + " and ".join(parts) + "."


def _variants_order(w: _Writer) -> str:
    v = _variants(w)
    if "dgse-o" not in v:
        raise _Missing("dgse-o")
    s, p, o = v[NETWORK_METHOD], v["dgse-p"], v["dgse-o"]
    counts = sorted(set(s) & set(p) & set(o))
    file = "variants/variants.csv"
    beats_p = [c for c in counts if w.num(s[c], "sl_error_m_mean") < w.num(p[c], "sl_error_m_mean")]
    same = [c for c in counts if _f2(w.num(s[c], "sl_error_m_mean")) == _f2(w.num(o[c], "sl_error_m_mean"))]
    s_lead = [
        c for c in counts if c not in same and w.num(s[c], "sl_error_m_mean") < w.num(o[c], "sl_error_m_mean")
    ]
    o_lead = [c for c in counts if c not in same and c not in s_lead]
    full = len(beats_p) == len(counts) and len(s_lead) == len(counts)
    text = (
        "**The paper's variant ordering is "
        + ("reproduced" if full else "only half reproduced" if beats_p else "not reproduced")
        + "** (`variants`): DGSE-S beats DGSE-P "
        + (_counts_text(beats_p, counts, w, file) if beats_p else "at no count")
    )
    parts = []
    if s_lead:
        c = s_lead[-1]
        parts.append(
            f"DGSE-S leads {_counts_text(s_lead, counts, w, file)} ({w.cell(s[c], 'sl_error_m_mean')} vs "
            f"{w.cell(o[c], 'sl_error_m_mean')} m at {w.cell(s[c], 'n_obs', _int)})"
        )
    if same:
        c = same[-1]
        parts.append(
            f"the two tie {_counts_text(same, counts, w, file)} ({w.cell(s[c], 'sl_error_m_mean')} m both at "
            f"{w.cell(s[c], 'n_obs', _int)})"
        )
    if o_lead:
        c = o_lead[-1]
        parts.append(
            f"DGSE-O leads {_counts_text(o_lead, counts, w, file)} ({w.cell(o[c], 'sl_error_m_mean')} vs "
            f"{w.cell(s[c], 'sl_error_m_mean')} m at {w.cell(s[c], 'n_obs', _int)})"
        )
    if not full:
        text += ", and against DGSE-O, the source-only network: " + "; ".join(parts)
    text += "."
    try:
        text += _steps_note(w)
    except _Missing:
        pass
    cf = [c for c in counts if w.num(p[c], "cf_rmse_mean") < w.num(s[c], "cf_rmse_mean")]
    tail = []
    for c in reversed(counts):
        if c not in cf:
            break
        tail.insert(0, c)
    if tail:
        c = tail[-1]
        text += (
            f" From many readings DGSE-P maps concentration better than DGSE-S (log RMSE lower "
            f"{_counts_text(tail, counts, w, file)}: {w.cell(p[c], 'cf_rmse_mean')} vs "
            f"{w.cell(s[c], 'cf_rmse_mean')} "
            f"at {w.cell(s[c], 'n_obs', _int)})."
        )
    return text


def _steps_note(w: _Writer) -> str:
    text = " ".join(s.get("text", "") for s in w.results.manifest("variants").get("sections", []))
    found = {m.group(1): int(m.group(3)) for m in _CHECKPOINT.finditer(text)}
    if "DGSE-O" not in found or "DGSE-S" not in found:
        raise _Missing("steps")
    more = found["DGSE-O"] / found["DGSE-S"] - 1
    if more <= 0.1:
        return ""
    how = "DGSE-O steps / DGSE-S steps - 1"
    pct = w.value(100 * more, _sig2, files=["variants/suite.json"], how=how)
    return (
        f" DGSE-O's checkpoint took {pct} % more optimizer steps than DGSE-S's; the README (*Models*) "
        "compares the two at equal steps."
    )


def _samples_latency(w: _Writer) -> str:
    rows = w.results.rows("samples", "samples_latency", ("map_cells", "K=T", "precision"))
    by = {(x["map_cells"], x["K=T"], x["precision"]): x for x in rows}
    sizes = sorted({x["map_cells"] for x in rows}, key=lambda s: int(str(s).split("x")[0]))
    size = sizes[0]
    ks = sorted({x["K=T"] for x in rows})
    k = 5 if 5 in ks else ks[-1]
    fast = by.get((size, k, "bf16+channels_last"))
    f32 = by.get((size, k, "float32"))
    if fast is None or f32 is None:
        raise _Missing("latency rows")
    side = w.text(str(size).replace("x", " x "), "samples/samples_latency.csv", "map_cells")
    return (
        f"**Latency** (`samples`): one full estimate with K = T = {w.cell(fast, 'K=T', _int)} on a "
        f"{side} map takes {w.cell(fast, 'seconds_median', _seconds)} s in `bf16+channels_last` on "
        f"{w.cell(fast, 'threads', _int)} CPU threads ({w.cell(f32, 'seconds_median', _seconds)} s in "
        "`float32`)."
    )


def _samples_quality(w: _Writer) -> str:
    rows = w.results.rows("samples", "samples_quality", ("K", "T"))
    one = [x for x in rows if x["K"] == 1 and x["T"] == 1]
    five = [x for x in rows if x["K"] == 5 and x["T"] == 5]
    if not one or not five:
        raise _Missing("samples rows")
    r = five[0]
    ce, nll = w.num(r, "ce rel. reduction % all"), w.num(r, "cf_nll rel. reduction % all")
    size = "little" if max(ce, nll) < 1 else "some"
    return (
        f"**Monte Carlo samples help {size}** (`samples`): K = T = {w.cell(r, 'K', _int)} lowers the "
        "source CE by "
        f"{w.cell(r, 'ce rel. reduction % all', _sig2)} % and the concentration NLL by "
        f"{w.cell(r, 'cf_nll rel. reduction % all', _sig2)} % against one sample."
    )


SEARCH_KEY = ("scenario", "method")


def _search_all(w: _Writer, table: str) -> dict[str, _Row]:
    return {x["method"]: x for x in w.results.rows("search", table, SEARCH_KEY) if x["scenario"] == "all"}


def _found(w: _Writer, row: _Row) -> tuple[str, str]:
    """``(found, episodes)`` of an "all" row: the success rate times the episodes."""
    n = w.num(row, "trials")
    k = round(w.num(row, "SR [%]") / 100 * n)
    return (
        w.value(k, _int, [(row, "SR [%]"), (row, "trials")], "SR x episodes"),
        w.value(n, _int, [(row, "trials")], "episodes"),
    )


def _plan(w: _Writer) -> tuple[str, str]:
    """``(scenarios, trials)`` of the search suite's comparison, as written."""
    plan = w.results.json("search", "search_results.json")["plan"]
    file = ["search/search_results.json"]
    n = w.value(plan["n_compare"], _int, files=file, how="plan.n_compare")
    t = int(plan["trials"])
    trials = "one trial" if t == 1 else f"{w.value(t, _int, files=file, how='plan.trials')} trials"
    return n, trials


def _search_phys(w: _Writer) -> str:
    steady, fil = _search_all(w, "search_steady"), _search_all(w, "search_filament")
    phys = w.label(PHYSICS_METHOD)
    ps, pf = steady[phys], fil[phys]
    n_scen, trials = _plan(w)
    ks, ns = _found(w, ps)
    kf, nf = _found(w, pf)
    s_s, s_f = _found(w, steady["DGSE-S"])[0], _found(w, fil["DGSE-S"])[0]
    base = [x for m, x in steady.items() if m not in (phys, "DGSE-S")] + [
        x for m, x in fil.items() if m not in (phys, "DGSE-S")
    ]

    def found(x: _Row) -> int:
        return round(w.num(x, "SR [%]") / 100 * w.num(x, "trials"))

    base_found = [found(x) for x in base]
    lo = w.value(min(base_found), _int, [(x, "SR [%]") for x in base], "min found")
    hi = w.value(max(base_found), _int, [(x, "SR [%]") for x in base], "max found")
    most = all(found(ps) >= found(x) for x in steady.values()) and all(
        found(pf) >= found(x) for x in fil.values()
    )
    slow = all(w.num(ps, "ST [s]") >= w.num(x, "ST [s]") for x in steady.values())
    level = w.results.manifest("search").get("knowledge", "map")
    head = f"{phys} finds the most sources" if most else f"{phys} is not the one that finds the most sources"
    text = (
        f"**Active search at `{level}`: {head}{', slowly' if slow else ''}** (`search`, {n_scen} test "
        f"scenarios, {trials} each): {ks} of {ns} with steady readings (mean error "
        f"{w.cell(ps, 'error [m]')} m, ST {w.cell(ps, 'ST [s]', _int)} s, {w.cell(ps, 'steps', _int)} steps) "
        f"and {kf} of {nf} with filament readings ({w.cell(pf, 'error [m]')} m, ST "
        f"{w.cell(pf, 'ST [s]', _int)} s), against DGSE-S's {s_s} and {s_f} of {ns} and the baselines' "
        f"{lo if lo == hi else lo + '-' + hi} of {ns}."
    )
    try:
        text += " " + _search_stops(w)
    except _Missing:
        pass
    text += (
        f" One step takes {w.cell(ps, 'step [s]', _seconds)} s (steady) and "
        f"{w.cell(pf, 'step [s]', _seconds)} s (filament) on the suite's {_threads(w, 'search')}. "
        "(Its searches on more test scenarios are in the README's `dgse-phys` summary.)"
    )
    return text


#: Where a search result's ``planner_options`` hold the deadline margin: the dotted key a run
#: writes, and the flat name of the results recorded before the planner's settings objects.
_MARGIN_KEYS = ("deadline.margin_s", "deadline_margin_s")


def _deadline_margin(settings: dict[str, Any]) -> tuple[Any, str] | None:
    """``(margin, key)``: the deadline margin a search result's settings record and where, else None."""
    options = settings.get("planner_options") or {}
    for key in _MARGIN_KEYS:
        if options.get(key) is not None:
            return options[key], key
    nested = options.get("deadline")
    if isinstance(nested, dict) and nested.get("margin_s") is not None:
        return nested["margin_s"], "deadline.margin_s"
    return None


def _search_stops(w: _Writer) -> str:
    from dgse.search.metrics import SUCCESS_RADIUS_M

    episodes, margin, margin_key = [], None, ""
    files = []
    for kind in ("test", "filament"):
        name = f"run_{PHYSICS_METHOD}_{kind}.json"
        d = w.results.json("search", name)
        files.append(f"search/{name}")
        found = _deadline_margin(d.get("settings") or {})
        if found is not None:
            margin, margin_key = found
        episodes += [t for c in d["per_case"] for t in c["trials"]]
    if not episodes:
        raise _Missing("episodes")
    conf = [t for t in episodes if t.get("reason") == "converged"]
    late = [t for t in episodes if t.get("reason") == "deadline"]
    near = [t for t in late if t["error_m"] <= SUCCESS_RADIUS_M]
    n = w.value(len(episodes), _int, files=files, how="episodes")
    text = (
        f"Only {w.value(len(conf), _int, files=files, how='reason converged')} of its {n} searches "
        "stopped on a confident posterior ("
        + _seq(
            [
                w.value(t["error_m"], _f2, files=files, how="error_m")
                for t in sorted(conf, key=lambda t: t["error_m"])
            ]
        )
        + " m off)"
    )
    if late:
        k = w.value(len(late), _int, files=files, how="reason deadline")
        text += f"; the other {k} ran to the deadline stop"
        if margin is not None:
            s = w.value(margin, _int, files=files, how=f"planner_options.{margin_key}")
            text += f" ({s} s before the time limit)"
        text += (
            f", {w.value(len(near), _int, files=files, how='deadline stops within')} of them within "
            f"{w.value(SUCCESS_RADIUS_M, _int, how='dgse.search.metrics.SUCCESS_RADIUS_M')} m"
        )
    return text + "."


def _search_dgse_s(w: _Writer) -> str:
    steady, fil = _search_all(w, "search_steady"), _search_all(w, "search_filament")
    summ = {x["readings"]: x for x in w.results.rows("search", "dgse_s_summary", ("readings",))}
    ks, ns = _found(w, steady["DGSE-S"])
    kf, _ = _found(w, fil["DGSE-S"])
    n_scen, trials = _plan(w)
    text = (
        f"**Active search with DGSE-S is far from the paper** (`search`): DGSE-S with the utility planner "
        f"finds {ks} of {ns} sources with steady readings and {kf} of {ns} with filament readings "
        f"({n_scen} scenarios, {trials} each)"
    )
    if {"steady", "filament"} <= set(summ):
        st, fl = summ["steady"], summ["filament"]
        text += (
            f", and succeeds in {w.cell(st, 'SR [%]', _sig2)} % of {w.cell(st, 'scenarios', _int)} steady "
            "scenarios "
            "(mean error "
            f"{w.cell(st, 'error [m]', _sig2)} m) and {w.cell(fl, 'SR [%]', _sig2)} % of the same "
            f"{w.cell(fl, 'scenarios', _int)} with filament readings ({w.cell(fl, 'error [m]', _sig2)} m)"
        )
    base = [
        x for m, x in list(steady.items()) + list(fil.items()) if m not in ("DGSE-S", w.label(PHYSICS_METHOD))
    ]
    mine = max(w.num(steady["DGSE-S"], "SR [%]"), w.num(fil["DGSE-S"], "SR [%]"))
    better = "do no better" if max(w.num(x, "SR [%]") for x in base) <= mine else "do better"
    text += (
        f", against the paper's success rates; the baselines {better} "
        f"({w.span([(x, 'SR [%]') for x in base], _int, ' %')})."
    )
    try:
        text += " " + _dgse_s_failures(w)
    except _Missing:
        pass
    try:
        e75 = {x["environment"]: x for x in w.results.rows("search", "ood_eta075", ("environment",))}["all"]
        e88 = {x["environment"]: x for x in w.results.rows("search", "ood_eta088", ("environment",))}["all"]
        k1, n1 = _found(w, e75)
        k2, _ = _found(w, e88)
        text += (
            f" Out of domain it finds {k1} of {n1} with the paper's threshold and {k2} of {n1} with the "
            "tuned one."
        )
    except (_Missing, KeyError):
        pass
    text += (
        f" One step takes {w.cell(steady['DGSE-S'], 'step [s]', _seconds)} s on the suite's "
        f"{_threads(w, 'search')} "
        "(the README's *Active search* times it on both cores)."
    )
    return text


def _dgse_s_failures(w: _Writer) -> str:
    rows = w.results.rows("search", "dgse_s_per_scenario", ("readings", "scenario"))
    plan = w.results.json("search", "search_results.json")["plan"]
    limit = float(plan["time_limit_s"])
    fail = [x for x in rows if w.num(x, "SR [%]") == 0]
    timeouts = [x for x in fail if w.num(x, "ST [s]") >= limit]
    wrong = [x for x in fail if w.num(x, "ST [s]") < limit]
    if not fail:
        raise _Missing("no failures")

    def by(kind: str, xs: list[_Row]) -> str:
        return w.value(
            sum(1 for x in xs if x["readings"] == kind), _int, [(x, "ST [s]") for x in xs], "count"
        )

    lim = w.value(limit, _int, files=["search/search_results.json"], how="plan.time_limit_s")
    return (
        f"Its failures on those scenarios are of two kinds: searches that stopped on a confident but wrong "
        f"posterior ({by('steady', wrong)} steady, {by('filament', wrong)} filament) and searches that ran "
        "to "
        f"the {lim} s limit ({by('steady', timeouts)} and {by('filament', timeouts)}) whose broad posteriors "
        "never reached the entropy threshold."
    )


#: The statements, in the order the summary lists them, under their heading.
WINS: tuple[Callable[[_Writer], str], ...] = (
    _gdm_uncertainty,
    _gsl,
    _calibration_win,
    _variants_fields,
    _samples_latency,
)
LOSSES: tuple[Callable[[_Writer], str], ...] = (
    _gdm_ppm_rmse,
    _variants_order,
    _search_phys,
    _search_dgse_s,
    _calibration_conc,
    _calibration_phys,
    _samples_quality,
)


FIELD_KEY = ("group", "method")
#: The columns of the ``field`` table in the summary: the suite's column, its heading here and
#: its format; the paper's row reads the column of ``paper_dgse_s.csv`` named last (or none).
FIELD_COLUMNS: tuple[tuple[str, str, Callable[[float], str], str | None], ...] = (
    ("episodes", "episodes", _int, None),
    ("SR [%]", "SR %", lambda x: f"{x:.0f}", "SR [%]"),
    ("error [m]", "error m", _f2, "error [m]"),
    ("ST mean [s]", "ST mean s", _sig3, "ST [s]"),
    ("ST median [s]", "ST median s", _sig3, None),
    ("TD [m]", "TD m", _sig3, "TD [m]"),
    ("PER median", "PER median", _f2, "PER"),
    ("step median [s]", "step median s", _seconds, "step [s]"),
    ("shortest-path time [s]", "shortest-path time s", _sig3, None),
)


def _field_table(w: _Writer, suite: str) -> list[str]:
    """The ``field`` suite's table (``field_search.csv``) with the paper's DGSE-S row beside it."""
    rows = w.results.rows(suite, "field_search", FIELD_KEY)
    if not rows:
        raise _Missing(f"{suite}/field_search.csv: no rows")
    plan = w.results.json(suite, "field_results.json")["plan"]
    file = [f"{suite}/field_results.json"]
    level = w.results.manifest(suite).get("knowledge", "map")
    limit = w.value(plan["time_limit_s"], _int, files=file, how="plan.time_limit_s")
    t = int(plan["trials"])
    trials = "one trial" if t == 1 else f"{w.value(t, _int, files=file, how='plan.trials')} trials"

    def cell(row: _Row, column: str, fmt: Callable[[float], str]) -> str:
        v = row.get(column)
        if not isinstance(v, (int, float)) or isinstance(v, bool) or not math.isfinite(v):
            return "n/a"
        return w.cell(row, column, fmt)

    head = ["group", "method", *(h for _, h, _, _ in FIELD_COLUMNS)]
    lines = [
        f"**Search with filament readings** (`{suite}`, knowledge `{level}`, {trials} per "
        f"scenario, time limit {limit} s): SR counts the searches the method ended itself with its "
        "estimate within 2 m; the shortest-path time is the least a search from the same starts takes "
        "(the shortest path at the robot's speed plus one reading).",
        "",
        "| " + " | ".join(head) + " |",
        "|" + "|".join("---" for _ in head) + "|",
    ]
    for row in rows:
        cells = [str(row["group"]), str(row["method"])]
        cells += [cell(row, column, fmt) for column, _, fmt, _ in FIELD_COLUMNS]
        lines.append("| " + " | ".join(cells) + " |")
    try:
        paper = w.results.rows(suite, "paper_dgse_s", ("environment",))
        mean = w.results.row(suite, "paper_dgse_s", ("environment",), environment="mean")
        envs = [r for r in paper if r["environment"] != "mean"]
        n = w.value(len(envs), _int, files=[f"{suite}/paper_dgse_s.csv"], how="environments")
        cells = ["paper", f"DGSE-S (mean of its {n} GADEN environments)"]
        cells += ["" if p is None else cell(mean, p, fmt) for _, _, fmt, p in FIELD_COLUMNS]
        lines.append("| " + " | ".join(cells) + " |")
        lines += [
            "",
            "The paper's row: the means over its environments of its DGSE-S table "
            "(`tab:active_search_results`; PER: the mean of the in-domain values its appendix "
            "lists), not run here.",
        ]
    except _Missing:
        pass
    return lines


def _field(w: _Writer) -> list[str]:
    """A section with the ``field`` table of every level it was run at ([] for none)."""
    out: list[str] = []
    for level in LEVELS:
        suite = _suite_at("field", level)
        if not w.results.has(suite):
            continue
        before = len(w.cited)
        try:
            out += [*_field_table(w, suite), ""]
        except _Missing:
            del w.cited[before:]
    return ["## Search with filament readings", "", *out] if out else []


def build_summary(directory: str | os.PathLike[str]) -> tuple[str, list[Cited]]:
    """The Markdown of the summary of the suites under ``directory`` and the numbers it cites."""
    w = _Writer(_Results(Path(directory)))
    lines = ["# DGSE on our data: where DGSE-S and dgse-phys win, where they lose, and by how much", ""]
    lines += [_intro(w), ""]
    for title, statements in (("Wins", WINS), ("Losses", LOSSES)):
        items = []
        for statement in statements:
            before = len(w.cited)
            try:
                items.append(statement(w))
            except _Missing:
                del w.cited[before:]  # a statement left out cites nothing
        if items:
            lines += [f"## {title}", ""] + [f"- {item}" for item in items] + [""]
    lines += _field(w)
    return "\n".join(lines), w.cited


def write_summary(directory: str | os.PathLike[str], output: str | os.PathLike[str] | None = None) -> Path:
    """Write the summary of the suites under ``directory`` (``DIR/summary.md`` by default)."""
    text, _ = build_summary(directory)
    out = Path(output) if output is not None else Path(directory) / SUMMARY_NAME
    return write_text(out, text)
