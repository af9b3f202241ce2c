"""A benchmark output directory shared by the quick suite tests (its scenarios are solved once)."""

from __future__ import annotations

from pathlib import Path

import pytest

from dgse.bench.core import BenchContext


@pytest.fixture(scope="session")
def bench_root(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """An output root whose two quick ``test`` scenarios already exist."""
    root = tmp_path_factory.mktemp("bench")
    BenchContext("setup", root, quick=True).scenarios(2, "test")
    return root
