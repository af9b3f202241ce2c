"""Choose where dgse-phys's proportional noise takes its concentrations, on generated validation scenarios.

Table I's gas noise is ``alpha_g c + sigma_env``: proportional to the true concentration
at the sensor.  The evidence (:func:`dgse.posterior.adjoint.adjoint_log_evidence`)
models it as ``sigma (1 + kappa c_i / cbar)`` with ``c_i`` either a plug-in (the
posterior-predictive mean of a homoscedastic first pass, the same for every candidate:
``"plug-in"``), or each candidate's own prediction (``"candidate"``); dgse-phys averages
the two posteriors (``"mixture"``, :data:`dgse.posterior.mixture.MIXED_NOISE_WEIGHTS`).
Source-localization error and cross-entropy of ``dgse-phys --knowledge openings`` with
each (one alone: this script cuts the estimator's noise models to it), from 5 to 300
random readings (Table I noise), 2 trials on each of 12 generated
scenarios (seeds 900-911, a range kept for validation).

    python benchmarks/tune_phys_noise_weights.py -o benchmarks/results/phys_noise_weights.json
    python benchmarks/tune_phys_noise_weights.py --settings candidate candidate-T50 candidate-T25 \
        -o benchmarks/results/phys_noise_weights_tempering.json
"""

from __future__ import annotations

import argparse
from pathlib import Path

from phys_tuning import sweep, write_rows  # this folder's

import dgse.estimators.phys as phys

SEEDS = range(900, 912)
COUNTS = (5, 20, 50, 150, 300)
#: per setting, (the noise models the estimator mixes, its options)
SETTINGS: dict[str, tuple[tuple[str, ...], dict]] = {
    "plug-in": (("plug-in",), {}),
    "candidate": (("candidate",), {}),
    "mixture": (("plug-in", "candidate"), {}),
}
# the candidate weights with the tempering of more readings (``T = max(1, m / effective_readings)``,
# 100 by default at ``openings``): a sharper likelihood may need more of it
SETTINGS.update({f"candidate-T{m}": (("candidate",), {"evidence.effective_readings": m}) for m in (50, 25)})


def options(name: str) -> dict:
    """The estimator options of setting ``name``; the estimator built next mixes its noise models
    (``sweep`` builds each setting's estimator right after asking for its options)."""
    modes, opts = SETTINGS[name]
    phys.MIXED_NOISE_WEIGHTS = modes
    return opts


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("-o", "--out", type=Path, default=Path("benchmarks/results/phys_noise_weights.json"))
    ap.add_argument("--seeds", type=int, default=len(SEEDS), help="only the first N scenarios")
    ap.add_argument("--trials", type=int, default=2)
    ap.add_argument("--settings", nargs="+", choices=sorted(SETTINGS), default=list(SETTINGS))
    args = ap.parse_args()
    names = list(args.settings)
    seeds = list(SEEDS)[: args.seeds]
    err, ce = sweep("openings", names, options, seeds, COUNTS, trials=args.trials)
    write_rows(args.out, err, ce, names, COUNTS, {"seeds": seeds, "trials": args.trials})


if __name__ == "__main__":
    main()
