"""BLAS threads for the many small dense products of the physics estimators.

The adjoint evidence is a handful of ``(m, N)`` matrix-vector products per
flow hypothesis (``m`` readings up to a few hundred, ``N`` free cells): far
too small to share between threads.  With OpenBLAS's default of one thread
per core, each product starts and joins threads; when anything else runs on
the machine (a second search, a training job, the robot's own software) the
threads wait for each other and a product that takes 0.3 ms on one thread
took 10-12 ms on this project's 2-core machine (``w @ A`` with ``A`` of
``150 x 6000``).  :func:`one_blas_thread` runs a block with one BLAS thread
(``threadpoolctl``; a no-op where it finds no BLAS library to limit).

Independent pieces of one estimate (the evidence of each flow hypothesis, the
chunks of candidates of the zero readings' correction) run on the machine's
cores with :func:`map_threads` instead: NumPy, SciPy's
sparse solves and its special functions release the GIL, so Python threads
share the work without copying the arrays to other processes.
"""

from __future__ import annotations

import functools
import os
from collections.abc import Callable, Iterable, Iterator, Sequence
from concurrent.futures import ThreadPoolExecutor
from contextlib import contextmanager
from typing import Any, TypeVar

__all__ = ["map_threads", "one_blas_thread", "side_by_side", "with_one_blas_thread"]

_T = TypeVar("_T")
_R = TypeVar("_R")
#: Threads of :func:`map_threads` (the machine's cores, at most 2).
WORKERS = max(1, min(2, os.cpu_count() or 1))
_pool: ThreadPoolExecutor | None = None
_outer: ThreadPoolExecutor | None = None

_F = TypeVar("_F", bound=Callable[..., Any])
_controller: Any = None


@contextmanager
def one_blas_thread() -> Iterator[None]:
    """Run the block with BLAS limited to one thread (restored afterwards)."""
    global _controller
    if _controller is None:
        from threadpoolctl import ThreadpoolController

        _controller = ThreadpoolController()
    with _controller.limit(limits=1, user_api="blas"):
        yield


def with_one_blas_thread(func: _F) -> _F:
    """Decorator: :func:`one_blas_thread` around every call of ``func``."""

    @functools.wraps(func)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        with one_blas_thread():
            return func(*args, **kwargs)

    return wrapper  # type: ignore[return-value]


def map_threads(func: Callable[[_T], _R], items: Iterable[_T]) -> list[_R]:
    """``[func(x) for x in items]``, the calls spread over :data:`WORKERS` threads.

    For independent NumPy/SciPy work that releases the GIL.  ``func`` must not itself
    wait on :func:`map_threads` (the pool is shared).  With one item or one core, the
    calls run in the caller's thread.  Exceptions propagate as from the plain loop.
    """
    global _pool
    work = list(items)
    if WORKERS < 2 or len(work) < 2:
        return [func(x) for x in work]
    if _pool is None:
        _pool = ThreadPoolExecutor(WORKERS, thread_name_prefix="dgse-map")
    return list(_pool.map(func, work))


def side_by_side(funcs: Sequence[Callable[[], _R]]) -> list[_R]:
    """``[f() for f in funcs]``, each call in a thread of its own (:data:`WORKERS` at once).

    Unlike :func:`map_threads`'s, these calls may use :func:`map_threads`: their own
    threads are not the shared pool's, so their pieces queue on it together, and while
    one call waits for its slowest piece the other's pieces keep the cores busy.  With
    one call or one core, the calls run in the caller's thread.
    """
    global _outer
    work = list(funcs)
    if WORKERS < 2 or len(work) < 2:
        return [f() for f in work]
    if _outer is None:
        _outer = ThreadPoolExecutor(WORKERS, thread_name_prefix="dgse-side")
    return list(_outer.map(lambda f: f(), work))
