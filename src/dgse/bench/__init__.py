"""Benchmark suites that reproduce the paper's experiments, and the HTML report.

``dgse bench SUITE [--quick] --out DIR`` runs :func:`run_suite`; ``dgse report
DIR`` writes ``DIR/summary.md`` from the suites' result files
(:func:`dgse.bench.summary.write_summary`) and turns the results into one self-contained
HTML page (:func:`dgse.bench.report.write_report`).  Beside the suites, the package holds
what the measurement scripts of ``benchmarks/`` share: :mod:`dgse.bench.scenarios`,
:mod:`dgse.bench.parallel` and :mod:`dgse.bench.gdm_tuning`.  Each suite writes JSON, CSV and PNG
files plus a manifest ``suite.json`` into ``DIR/<suite>/``
(:mod:`dgse.bench.core`).

Suites (paper figure/table labels in brackets):

* ``variants``: DGSE-O/P/S over 5 to 300 observations [fig5];
* ``gdm``: DGSE-S against the gas distribution mapping baselines [fig7, fig8, fig9];
* ``gsl``: source localization from 50 random observations [fig:gsl_only];
* ``search``: active search against the baselines' planners, steady and
  filament readings, and out-of-domain layouts [tab:active_search_results,
  fig:path_compare, de];
* ``samples``: the K/T quality and latency trade-off and the surrogate
  objective check [App. C, App. B table object];
* ``calibration``: reliability and coverage of the predicted uncertainties;
* ``field``: active search with filament readings on paper-size test scenarios, office
  floors and GADEN-format scenarios, beside the paper's DGSE-S table
  [tab:active_search_results].
"""

from __future__ import annotations

import os
from collections.abc import Callable
from pathlib import Path
from typing import Any

from dgse.bench.core import BenchContext
from dgse.registry import Entry, Registry

__all__ = ["SUITES", "run_suite", "suite_names"]


#: The suites, in the order ``dgse bench all`` runs them; each entry's label is the suite's
#: title and its description says what it measures.
SUITES: Registry[Callable[[BenchContext], None]] = Registry(
    "suite",
    [
        Entry(
            "variants",
            "dgse.bench.variants:run",
            "DGSE variants (fig5)",
            description=(
                "DGSE-O, DGSE-P and DGSE-S on the test scenarios, 5 to 300 random observations: wind "
                "and concentration RMSE and NLL, source-localization error and cross-entropy."
            ),
        ),
        Entry(
            "gdm",
            "dgse.bench.gdm:run",
            "Gas distribution mapping (fig7, fig8, fig9)",
            description=(
                "DGSE-S against Kernel DM+V/W, G-GMRF, GW-GMRF and GaBP+: concentration RMSE and NLL "
                "in ppm for 50 to 250 observations, maps for 100 observations, computation time."
            ),
        ),
        Entry(
            "gsl",
            "dgse.bench.gsl:run",
            "Source localization from sparse observations (fig:gsl_only)",
            description=(
                "DGSE-S against the estimators of the field and the adjoint physics oracle, 50 random"
                " observations."
            ),
        ),
        Entry(
            "search",
            "dgse.bench.search:run",
            "Active search (tab:active_search_results, fig:path_compare, de)",
            description=(
                "Closed-loop search with each method's planner on steady and filament readings, and "
                "DGSE-S in out-of-domain layouts."
            ),
        ),
        Entry(
            "samples",
            "dgse.bench.samples:run",
            "Monte Carlo samples: quality, latency, surrogate objective (App. B, App. C)",
            description=(
                "How K and T change DGSE-S's concentration NLL, source cross-entropy and latency, and"
                " the Monte Carlo estimate of the original objective against the Jensen surrogate."
            ),
        ),
        Entry(
            "calibration",
            "dgse.bench.calibration:run",
            "Calibration of the predicted uncertainty",
            description=(
                "Reliability diagrams and 1/2-sigma coverage of the wind and concentration fields, "
                "and the expected calibration error of the source posterior."
            ),
        ),
        Entry(
            "field",
            "dgse.bench.field:run",
            "Search with filament readings: test, building and GADEN-format scenarios",
            description=(
                "Closed-loop search of every search method with the filament model's time-varying "
                "readings on the 20 paper-size test scenarios, 10 office floors of 20-30 m and 3 "
                "generated layouts exported to GADEN's scenario format and imported back: SR, error, "
                "ST, TD, PER, step time and the shortest-path time, beside the paper's DGSE-S table."
            ),
        ),
    ],
    ordered=True,
)


def suite_names() -> list[str]:
    """The suites in the order ``dgse bench all`` runs them."""
    return SUITES.names()


def run_suite(name: str, out: str | os.PathLike[str], **options: Any) -> Path:
    """Run suite ``name`` into ``out/<name>/`` and return its manifest path.

    ``options``: the run's keyword arguments of :class:`~dgse.bench.core.BenchContext`
    (``quick``, ``data``, ``seed``, ``knowledge``, ``progress``, ``command``); at a
    ``knowledge`` level where some methods do not work, those are left out, and the
    manifest says so.
    """
    info = SUITES.entry(name)
    ctx = BenchContext(name, out, title=info.display, description=info.description, **options)
    SUITES.factory(name)(ctx)
    return ctx.finish()
