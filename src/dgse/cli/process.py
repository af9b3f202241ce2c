"""The garbage collector of a ``dgse`` process, set for a command that runs once and exits.

A command imports NumPy, SciPy, numba and its own modules: some 10^5 objects
that live until the process ends.  With CPython's default thresholds the
cyclic collector runs some 250 times while they are imported and solved with
(0.08 s of a 1.55 s paper-size solve), and once more, over all of them, while
the interpreter shuts down (0.15 s).  :func:`start` raises the
first-generation threshold so that those passes are rare, :func:`finish`
moves every live object to the collector's permanent generation
(:func:`gc.freeze`) so that the shutdown does not scan them: 1.37 s for the
same solve (``python benchmarks/solver.py startup``,
``benchmarks/results/process_startup.md``).

Only the console script calls them (:func:`dgse.cli.main.run`), never a
library function or :func:`dgse.cli.main.main` called in-process: a
long-lived Python session keeps the defaults.  At shutdown, objects in a
reference cycle that is still alive then are not finalized; every file the
commands write is closed by the command itself.
"""

from __future__ import annotations

import gc

#: allocations (minus deallocations) between first-generation collections; CPython's default is 700
GEN0_THRESHOLD = 50_000


def start() -> None:
    """Collect the youngest generation every :data:`GEN0_THRESHOLD` net allocations (older ones as before)."""
    _, gen1, gen2 = gc.get_threshold()
    gc.set_threshold(GEN0_THRESHOLD, gen1, gen2)


def finish() -> None:
    """Leave every object alive now out of the collector's remaining passes (the shutdown's)."""
    gc.freeze()
