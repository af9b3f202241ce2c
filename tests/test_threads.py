"""``dgse.threads``: the shared worker threads keep the plain loop's order and errors."""

from __future__ import annotations

import numpy as np
import pytest

import dgse.threads as threads


@pytest.mark.parametrize("workers", [1, 2])
def test_map_threads_is_the_plain_loop(monkeypatch: pytest.MonkeyPatch, workers: int) -> None:
    monkeypatch.setattr(threads, "WORKERS", workers)
    rng = np.random.default_rng(0)
    mats = [rng.standard_normal((50, 50)) for _ in range(7)]
    got = threads.map_threads(lambda a: np.linalg.solve(a, np.ones(50)), mats)
    want = [np.linalg.solve(a, np.ones(50)) for a in mats]
    assert len(got) == len(want)
    for g, w in zip(got, want, strict=True):
        np.testing.assert_array_equal(g, w)
    assert threads.map_threads(lambda x: x, []) == []


def test_map_threads_raises_the_callers_error(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(threads, "WORKERS", 2)

    def f(x: int) -> int:
        if x == 3:
            raise ValueError("bad item 3")
        return x

    with pytest.raises(ValueError, match="bad item 3"):
        threads.map_threads(f, range(6))


@pytest.mark.parametrize("workers", [1, 2])
def test_side_by_side_calls_may_use_the_shared_pool(monkeypatch: pytest.MonkeyPatch, workers: int) -> None:
    monkeypatch.setattr(threads, "WORKERS", workers)
    rng = np.random.default_rng(1)
    groups = [[rng.standard_normal((40, 40)) for _ in range(5)] for _ in range(3)]

    def solve_all(mats: list[np.ndarray]) -> list[np.ndarray]:
        return threads.map_threads(lambda a: np.linalg.solve(a, np.ones(40)), mats)

    got = threads.side_by_side([lambda g=g: solve_all(g) for g in groups])
    assert len(got) == len(groups)
    for out, mats in zip(got, groups, strict=True):
        for g, a in zip(out, mats, strict=True):
            np.testing.assert_array_equal(g, np.linalg.solve(a, np.ones(40)))

    def fail() -> None:
        raise RuntimeError("second call failed")

    with pytest.raises(RuntimeError, match="second call failed"):
        threads.side_by_side([lambda: 1, fail])
