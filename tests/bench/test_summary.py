"""summary.md is written from the suites' result files: its numbers are the tables' numbers."""

from __future__ import annotations

import csv
import json
import re
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from dgse.bench.core import MANIFEST, BenchContext
from dgse.bench.report import write_report
from dgse.bench.summary import SUMMARY_NAME, Cited, build_summary, write_summary

REPO = Path(__file__).resolve().parents[2]
COMMITTED = REPO / "benchmarks" / "results" / "report"

GDM = ("dgse-s", "kdmvw", "ggmrf", "gwgmrf", "gabp")
NLL = ("dgse-s", "ggmrf", "gwgmrf")
SEARCH = ("DGSE-S", "DGSE-phys", "Dual-mode", "GrGSL", "PMFS", "Infotaxis (PF)")


def _suite(root: Path, name: str, knowledge: str = "map", text: str = "") -> BenchContext:
    return BenchContext(
        name, root, knowledge=knowledge, command=f"dgse bench {name}", title=name, description=text
    )


def _finish(ctx: BenchContext, threads: int = 1) -> None:
    path = ctx.finish()
    m = json.loads(path.read_text())
    m["environment"]["torch_threads"] = threads  # what a run with torch loaded records
    m["data"] = {"store": "/data/store.h5", "split": "test", "layouts": ["a", "b"]}
    path.write_text(json.dumps(m))


def _ms(rng: np.random.Generator, lo: float, hi: float) -> str:
    """A "mean (std)" cell as the search tables write it."""
    return f"{rng.uniform(lo, hi):.3f} ({rng.uniform(0, 1):.3f})"


def _seeded(root: Path, seed: int = 0) -> Path:
    """Small results of every suite the summary reads, drawn from ``seed``."""
    rng = np.random.default_rng(seed)
    counts = [50, 100, 250]
    scen = [f"layout-{k:06d}_src0" for k in range(3)]
    # gdm
    ctx = _suite(root, "gdm")
    sec = ctx.section("gdm")
    per, ppm, log = [], [], []
    for m in GDM:
        for n in counts:
            for s in scen:
                per.append(
                    {
                        "method": m,
                        "scenario": s,
                        "n_obs": n,
                        "cf_rmse_ppm_mean": rng.uniform(500, 3000),
                        "cf_nll_ppm_mean": rng.uniform(4, 11),
                        "nll_comparable": m in NLL,
                    }
                )
            row = {"method": m, "n_obs": n, "nll_comparable": m in NLL}
            ppm.append(
                {**row, "cf_rmse_ppm_mean": rng.uniform(500, 3000), "cf_nll_ppm_mean": rng.uniform(4, 11)}
            )
            log.append({**row, "cf_rmse_mean": rng.uniform(1, 4), "cf_nll_mean": rng.uniform(1, 8)})
    sec.table("fig8_gdm_per_scenario", per, "per scenario")
    sec.table("gdm_overall_ppm", ppm, "ppm")
    sec.table("gdm_overall_log", log, "log")
    _finish(ctx)
    # gsl at three levels
    for level, methods in (
        ("map", ("dgse-s", "dgse-phys", "dualmode", "pmfs")),
        ("openings", ("dgse-s", "dgse-phys", "dualmode", "pmfs", "adjoint")),
        ("wind", ("dgse-s", "dgse-phys", "dualmode", "pmfs", "adjoint", "adjoint-oracle")),
    ):
        ctx = _suite(root, "gsl", level)
        rows = []
        for m in methods:
            trials = 3 if m == "pmfs" else 20
            for s in [*scen, "all"]:
                rows.append(
                    {
                        "method": m,
                        "scenario": s,
                        "trials": trials * (len(scen) if s == "all" else 1),
                        "sl_error_m_mean": rng.uniform(0.5, 4),
                        "sl_error_m_median": rng.uniform(0.4, 3),
                        "ce_mean": rng.uniform(5, 14),
                        "seconds_median": rng.uniform(0.05, 3),
                        "oracle": m == "adjoint-oracle",
                    }
                )
        ctx.section("gsl").table("gsl_only", rows, "gsl")
        ctx.save_json("eval_dgse-s", {"observation_counts": [50], "trials": 20})
        _finish(ctx)
    # calibration at three levels
    for level in ("map", "openings", "wind"):
        ctx = _suite(root, "calibration", level)
        rows = [
            {
                "method": m,
                "n_obs": n,
                **{
                    c: rng.uniform(0.6, 0.99)
                    for c in ("wind_cov_1sigma", "wind_cov_2sigma", "conc_cov_1sigma", "conc_cov_2sigma")
                },
                **{
                    c: rng.uniform(0.01, 0.3)
                    for c in ("wind_cal_error", "conc_cal_error", "source_cal_error")
                },
                "source_median_level": rng.uniform(0.1, 0.49),
            }
            for m in ("dgse-s", "dgse-phys")
            for n in (25, 100, 300)
        ]
        ctx.section("calibration").table("calibration", rows, "calibration")
        _finish(ctx)
    # variants
    ctx = _suite(root, "variants")
    rows = []
    for m in ("dgse-o", "dgse-p", "dgse-s"):
        for n in (5, 10, 50, 100, 300):
            row: dict[str, Any] = {"method": m, "n_obs": n, "sl_error_m_mean": rng.uniform(1, 3)}
            if m != "dgse-o":
                row |= {
                    "wf_rmse_mean": rng.uniform(0.8, 1.1),
                    "cf_rmse_mean": rng.uniform(1, 3),
                    "cf_nll_mean": rng.uniform(1, 3),
                }
            rows.append(row)
    steps = rng.integers(1000, 6000, 3)
    text = (
        "Checkpoints: "
        + ", ".join(f"DGSE-{v} epoch 3 ({k} steps)" for v, k in zip("OPS", steps, strict=True))
        + "."
    )
    ctx.section("variants", text).table("variants", rows, "variants")
    _finish(ctx, threads=2)
    # samples
    ctx = _suite(root, "samples")
    sec = ctx.section("samples")
    lat = [
        {"map_cells": size, "K=T": k, "precision": p, "seconds_median": rng.uniform(0.01, 1), "threads": 2}
        for size in ("100x100", "200x200")
        for k in (1, 5)
        for p in ("float32", "bf16+channels_last")
    ]
    sec.table("samples_latency", lat, "latency")
    quality = [
        {
            "K": k,
            "T": t,
            "cf_nll rel. reduction % all": rng.uniform(0, 2),
            "ce rel. reduction % all": rng.uniform(0, 2),
        }
        for k, t in ((1, 1), (2, 2), (5, 5))
    ]
    sec.table("samples_quality", quality, "quality")
    _finish(ctx, threads=2)
    # search
    ctx = _suite(root, "search")
    sec = ctx.section("search")
    for table in ("search_steady", "search_filament"):
        rows = []
        for m in SEARCH:
            for s in [*scen, "all"]:
                rows.append(
                    {
                        "scenario": s,
                        "method": m,
                        "trials": len(scen) if s == "all" else 1,
                        "SR [%]": round(100 * rng.integers(0, len(scen) + 1) / len(scen), 1),
                        "error [m]": _ms(rng, 0.1, 5),
                        "ST [s]": _ms(rng, 50, 2000),
                        "step [s]": _ms(rng, 0.05, 0.6),
                        "steps": int(rng.integers(10, 500)),
                    }
                )
        sec.table(table, rows, table)
    sec.table(
        "dgse_s_summary",
        [
            {"readings": r, "scenarios": 4, "SR [%]": rng.uniform(0, 100), "error [m]": _ms(rng, 0.5, 5)}
            for r in ("steady", "filament")
        ],
        "summary",
    )
    sec.table(
        "dgse_s_per_scenario",
        [
            {
                "readings": r,
                "scenario": f"s{k}",
                "SR [%]": 0.0 if k % 2 else 100.0,
                "ST [s]": "300.0 (0.0)" if k % 3 else "300.0 (0.0)".replace("300", "400"),
            }
            for r in ("steady", "filament")
            for k in range(4)
        ],
        "per scenario",
    )
    for table in ("ood_eta075", "ood_eta088"):
        sec.table(
            table, [{"environment": "all", "trials": 4, "SR [%]": 25.0 * int(rng.integers(0, 5))}], table
        )
    ctx.save_json("search_results", {"plan": {"n_compare": len(scen), "trials": 1, "time_limit_s": 400.0}})
    for kind in ("test", "filament"):
        trials = [
            {"reason": reason, "error_m": float(rng.uniform(0, 6))}
            for reason in rng.choice(["converged", "deadline"], size=len(scen))
        ]
        ctx.save_json(
            f"run_dgse-phys_{kind}",
            {"settings": {"planner_options": {"deadline_margin_s": 60.0}}, "per_case": [{"trials": trials}]},
        )
    _finish(ctx)
    # field: the table per group and method, the paper's rows
    from dgse.bench.field import GROUPS, PAPER_COLUMNS, TABLE_COLUMNS, paper_rows

    ctx = _suite(root, "field")
    sec = ctx.section("field")
    rows = []
    for group, _ in GROUPS:
        for method in SEARCH:
            rows.append(
                {
                    "group": group,
                    "method": method,
                    "scenarios": 2,
                    "episodes": 4,
                    "SR [%]": 25.0 * int(rng.integers(0, 5)),
                    "error [m]": round(rng.uniform(0.1, 6), 3),
                    "ST mean [s]": round(rng.uniform(30, 2000), 1),
                    "ST median [s]": round(rng.uniform(30, 2000), 1),
                    "TD [m]": round(rng.uniform(1, 200), 2),
                    "PER median": None if method == "GrGSL" else round(rng.uniform(0.5, 9), 2),
                    "step median [s]": round(rng.uniform(0.01, 5), 4),
                    "shortest-path time [s]": round(rng.uniform(8, 60), 1),
                }
            )
    sec.table("field_search", rows, "field", TABLE_COLUMNS)
    sec.table("paper_dgse_s", paper_rows(), "paper", PAPER_COLUMNS)
    ctx.save_json("field_results", {"plan": {"trials": 2, "time_limit_s": 2000.0}})
    _finish(ctx)
    return root


@pytest.fixture
def seeded(tmp_path: Path) -> Path:
    return _seeded(tmp_path / "results")


def _cell(path: Path, key: tuple[tuple[str, Any], ...], column: str) -> float:
    """The number in ``column`` of the row of ``path`` whose key columns are ``key``, read here."""
    with path.open(newline="") as f:
        rows = list(csv.DictReader(f))

    def same(raw: str, v: Any) -> bool:
        return raw == str(v) or (
            isinstance(v, (int, float)) and raw not in ("", "True", "False") and float(raw) == v
        )

    got = [r for r in rows if all(same(r[k], v) for k, v in key)]
    assert len(got) == 1, (path, key)
    return float(got[0][column].split(" (")[0])


def _decimals(text: str) -> int:
    return len(text.split(".")[1]) if "." in text else 0


def _uncited_digits(text: str, cited: list[Cited]) -> list[str]:
    """What is left of ``text`` with digits once every cited number and every code span is gone."""
    text = re.sub(r"`[^`]*`", "", text)
    for c in sorted({c.text for c in cited}, key=len, reverse=True):
        text = re.sub(rf"(?<![\d.,]){re.escape(c)}(?![\d]|[.,]\d)", "#", text)
    return re.findall(r"\S*\d\S*", text)


def test_every_number_of_the_summary_is_cited(seeded: Path) -> None:
    text, cited = build_summary(seeded)
    for section in (
        "## Wins",
        "## Losses",
        "(`gdm`)",
        "(`gsl`",
        "(`gsl-openings`)",
        "(`variants`)",
        "(`search`",
        "(`field`",
        "| paper | DGSE-S",
    ):
        assert section in text
    assert _uncited_digits(text, cited) == []
    assert all(c.sources or c.how for c in cited)


def test_the_summary_numbers_are_the_csv_numbers(seeded: Path) -> None:
    _, cited = build_summary(seeded)
    checked = 0
    for c in cited:
        if c.how or len(c.sources) != 1 or not c.sources[0].column:
            continue
        src = c.sources[0]
        value = _cell(seeded / src.file, src.row, src.column)
        assert c.value == pytest.approx(value, rel=1e-12), c
        # written to its precision: the text is the value rounded
        shown = float(c.text.replace(",", ""))
        assert shown == pytest.approx(value * c.scale, abs=0.5 * 10 ** -_decimals(c.text) + 1e-9), c
        checked += 1
    assert checked >= 60


def test_ranges_are_the_extremes_of_their_cells(seeded: Path) -> None:
    _, cited = build_summary(seeded)
    spans = [c for c in cited if c.how in ("min", "max")]
    assert len(spans) >= 20
    for c in spans:
        values = [_cell(seeded / s.file, s.row, s.column) for s in c.sources]
        assert c.value == (min(values) if c.how == "min" else max(values))


def _gsl_all(root: Path, suite: str) -> dict[str, dict[str, str]]:
    with (root / suite / "gsl_only.csv").open(newline="") as f:
        return {r["method"]: r for r in csv.DictReader(f) if r["scenario"] == "all"}


def test_the_wording_follows_the_numbers(seeded: Path) -> None:
    from dgse.estimators.registry import ESTIMATORS

    for seed in range(3):
        root = _seeded(seeded.parent / f"r{seed}", seed)
        rows = _gsl_all(root, "gsl")
        best = min(rows, key=lambda m: float(rows[m]["sl_error_m_mean"]))
        text, _ = build_summary(root)
        assert f"at `map` {ESTIMATORS.label(best)} has the lowest mean error, " in text
        assert f"{float(rows[best]['sl_error_m_mean']):.2f} m, against" in text
        # a wins count among scenario x count cells of the NLL
        with (root / "gdm" / "fig8_gdm_per_scenario.csv").open(newline="") as f:
            per = list(csv.DictReader(f))
        cells: dict[tuple[str, str], dict[str, float]] = {}
        for r in per:
            if r["nll_comparable"] == "True":
                cells.setdefault((r["scenario"], r["n_obs"]), {})[r["method"]] = float(r["cf_nll_ppm_mean"])
        wins = sum(1 for c in cells.values() if min(c, key=c.__getitem__) == "dgse-s")
        where = f"in all {len(cells)}" if wins == len(cells) else f"in {wins} of {len(cells)}"
        assert f"concentration NLL (ppm) {where} scenario x count cells" in text


def test_a_suite_not_run_leaves_its_statements_out(seeded: Path) -> None:
    import shutil

    for name in ("gdm", "search"):
        shutil.rmtree(seeded / name)
    text, cited = build_summary(seeded)
    assert "(`gdm`)" not in text and "(`search`" not in text
    assert "(`gsl`" in text and "(`variants`)" in text
    assert _uncited_digits(text, cited) == []


def test_the_report_writes_the_summary_over_a_typed_one(seeded: Path) -> None:
    (seeded / SUMMARY_NAME).write_text("# typed by hand\n\nPMFS 3.63 m\n")
    page = write_report(seeded).read_text()
    summary = (seeded / SUMMARY_NAME).read_text()
    assert summary == build_summary(seeded)[0]
    assert "typed by hand" not in summary and "typed by hand" not in page
    assert page.index("where DGSE-S and dgse-phys win") < page.index('<nav class="toc"')


@pytest.mark.skipif(not (COMMITTED / MANIFEST).parent.is_dir(), reason="no committed report")
def test_the_committed_summary_is_the_one_its_results_give(tmp_path: Path) -> None:
    """benchmarks/results/report/summary.md is what `dgse report` writes from the files beside it."""
    committed = COMMITTED / SUMMARY_NAME
    out = write_summary(COMMITTED, tmp_path / SUMMARY_NAME)
    assert out.read_text() == committed.read_text()


@pytest.mark.parametrize(
    "options",
    [{"deadline_margin_s": 45.0}, {"deadline.margin_s": 45.0}, {"deadline": {"margin_s": 45.0}}],
    ids=["recorded", "dotted", "nested"],
)
def test_the_deadline_margin_is_read_by_its_recorded_and_its_settings_name(
    seeded: Path, options: dict[str, Any]
) -> None:
    """Results recorded before the planner's settings objects name the margin ``deadline_margin_s``;
    a run now writes the dotted key (or a mapping under ``deadline``)."""
    for kind in ("test", "filament"):
        path = seeded / "search" / f"run_dgse-phys_{kind}.json"
        d = json.loads(path.read_text())
        d["settings"]["planner_options"] = options
        path.write_text(json.dumps(d))
    text, cited = build_summary(seeded)
    assert "(45 s before the time limit)" in text
    assert [c.how for c in cited if c.text == "45"] == [
        "planner_options.deadline_margin_s"
        if "deadline_margin_s" in options
        else "planner_options.deadline.margin_s"
    ]


def test_the_field_table_has_a_row_per_group_and_method_and_the_papers(seeded: Path) -> None:
    from dgse.bench.field import GROUPS, PAPER_DGSE_S

    text, _ = build_summary(seeded)
    lines = [line for line in text.splitlines() if line.startswith("| ")]
    header, body = lines[0], lines[1:]
    assert header.startswith("| group | method | episodes | SR % |")
    assert [tuple(c.strip() for c in r.split("|")[1:3]) for r in body[:-1]] == [
        (g, m) for g, _ in GROUPS for m in SEARCH
    ]
    assert all(r.split("|")[9].strip() == "n/a" for r in body[:-1] if "| GrGSL |" in r)  # no PER
    paper = [c.strip() for c in body[-1].split("|")[1:-1]]
    assert paper[1] == f"DGSE-S (mean of its {len(PAPER_DGSE_S)} GADEN environments)"
    mean_st = sum(e["st_s"][0] for e in PAPER_DGSE_S) / len(PAPER_DGSE_S)
    assert paper[5] == f"{mean_st:.1f}"  # ST mean, three significant digits
    assert "1 trial(s)" not in text and "2 trials per scenario" in text
