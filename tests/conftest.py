"""Shared fixtures: tiny hand-made layouts and the OpenFOAM reference cases."""

from __future__ import annotations

import os
from pathlib import Path

import matplotlib
import numpy as np
import pytest

matplotlib.use("Agg")

from dgse.world.layout import Layout, Opening

REPO = Path(__file__).resolve().parents[1]


def reference_dir() -> Path:
    """``$DGSE_REFERENCE_CASES`` or ``../shared/reference-cases`` beside the repository."""
    env = os.environ.get("DGSE_REFERENCE_CASES")
    return Path(env) if env else (REPO.parent / "shared" / "reference-cases")


@pytest.fixture(scope="session")
def reference_cases_dir() -> Path:
    d = reference_dir()
    if not any(d.glob("*.npz")):
        pytest.fail(f"OpenFOAM reference cases not found in {d} (set DGSE_REFERENCE_CASES)")
    return d


def two_rooms(width: int = 30, height: int = 20) -> Layout:
    """``width x height`` cells: a wall at mid-width with a 4-cell door; inlet west, outlet east."""
    occ = np.zeros((height, width), dtype=np.uint8)
    mid = width // 2
    occ[:, mid] = 1
    occ[height // 2 - 2 : height // 2 + 2, mid] = 0
    h = 0.1
    return Layout(
        occ,
        (Opening("west", 0.6 * height * h, 0.9 * height * h),),
        (Opening("east", 0.1 * height * h, 0.4 * height * h),),
        name="two_rooms",
    )


@pytest.fixture
def two_rooms_layout() -> Layout:
    return two_rooms()
