"""Shared fixtures: tiny hand-made layouts and the committed OpenFOAM test cases."""

from __future__ import annotations

from pathlib import Path

import matplotlib
import numpy as np
import pytest

matplotlib.use("Agg")

from dgse.world.layout import Layout, Opening

REPO = Path(__file__).resolve().parents[1]


#: OpenFOAM case files committed with the tests (``python3 scripts/make_test_data.py`` makes them).
OPENFOAM_CASES = REPO / "tests" / "fixtures" / "openfoam"


@pytest.fixture(scope="session")
def openfoam_cases_dir() -> Path:
    """``tests/fixtures/openfoam``: one 5 x 5 m layout solved by OpenFOAM for two sources."""
    if not any(OPENFOAM_CASES.glob("small_src*.npz")):
        pytest.fail(
            f"OpenFOAM test cases missing from {OPENFOAM_CASES} "
            "(they are committed; remake them with `python3 scripts/make_test_data.py`)"
        )
    return OPENFOAM_CASES


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


@pytest.fixture
def factor_calls(monkeypatch: pytest.MonkeyPatch) -> list[int]:
    """The number of candidates of every call of the zeros' integrated factor
    (``adjoint._censored_log_factor``) while the test runs."""
    from dgse.posterior import adjoint

    seen: list[int] = []
    factor = adjoint._censored_log_factor

    def count(Bt, *args, **kwargs):
        seen.append(len(Bt))
        return factor(Bt, *args, **kwargs)

    monkeypatch.setattr(adjoint, "_censored_log_factor", count)
    return seen
