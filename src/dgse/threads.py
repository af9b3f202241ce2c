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
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any, TypeVar

__all__ = ["one_blas_thread", "with_one_blas_thread"]

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
