"""GADEN result import, on synthetic GADEN-format files written here."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from dgse.data.gaden import load_gaden, read_gaden_frame
from dgse.data.store import DatasetStore, cases_equal
from dgse.errors import InputDataError

ENV_MIN = (1.0, -2.0, 0.0)
SOURCE = (2.25, -0.95, 0.15)  # x, y, z in m (GADEN frame)


def gaden_fields(nx: int, ny: int, nz: int, cell: float, scale: float = 1.0):
    """Analytic fields on GADEN's grid: a Gaussian plume (ppm) and a uniform wind + shear."""
    x = ENV_MIN[0] + (np.arange(nx) + 0.5) * cell
    y = ENV_MIN[1] + (np.arange(ny) + 0.5) * cell
    z = ENV_MIN[2] + (np.arange(nz) + 0.5) * cell
    X, Y, Z = np.meshgrid(x, y, z, indexing="ij")  # (nx, ny, nz)
    conc = scale * 100.0 * np.exp(-((X - SOURCE[0]) ** 2 + (Y - SOURCE[1]) ** 2) / 0.5) * (1 + Z)
    u = 0.5 + 0.1 * (Y - ENV_MIN[1])
    v = -0.2 + 0.0 * X
    w = 0.01 + 0.0 * X
    return conc, u, v, w


def write_gaden(
    path: Path,
    nx: int,
    ny: int,
    nz: int,
    cell: float,
    scale: float = 1.0,
    *,
    header_override: dict[str, str] | None = None,
    drop_rows: int = 0,
    unit: str = "ppm",
) -> Path:
    """A GADEN filament-simulator ASCII snapshot (the format of its save_state_to_file)."""
    conc, u, v, w = gaden_fields(nx, ny, nz, cell, scale)
    head = {
        "env_min(m)": f"{ENV_MIN[0]:.4f} {ENV_MIN[1]:.4f} {ENV_MIN[2]:.4f}",
        "env_max(m)": f"{ENV_MIN[0] + nx * cell:.4f} {ENV_MIN[1] + ny * cell:.4f} "
        f"{ENV_MIN[2] + nz * cell:.4f}",
        "NumCells_XYZ": f"{nx} {ny} {nz}",
        "CellSizes_XYZ[m]": f"{cell:.4f} {cell:.4f} {cell:.4f}",
        "GasSourceLocation_XYZ[m]": f"{SOURCE[0]:.4f} {SOURCE[1]:.4f} {SOURCE[2]:.4f}",
        "GasType": "ethanol",
    }
    head.update(header_override or {})
    lines = [f"{k} {v}" for k, v in head.items() if v is not None]
    lines.append(f"Cell_x\t Cell_y\t Cell_z\t Gas_conc[{unit}]\t Wind_u[m/s]\t Wind_v[m/s]\t Wind_w[m/s]")
    rows = [
        f"{i} {j} {k} {conc[i, j, k]:f} {u[i, j, k]:f} {v[i, j, k]:f} {w[i, j, k]:f}"
        for i in range(nx)
        for j in range(ny)
        for k in range(nz)
    ]
    lines.extend(rows[: len(rows) - drop_rows])
    path.write_text("\n".join(lines) + "\n")
    return path


def write_obstacles(path: Path, w: int, h: int) -> Path:
    """Occupancy PGM (row 0 at the top): a solid block in the upper-left corner (high y, low x)."""
    img = np.full((h, w), 255, np.uint8)
    img[: h // 4, : w // 5] = 0
    Image.fromarray(img).save(path)
    return path


def scenario(tmp_path: Path, cell: float = 0.1, n_frames: int = 2) -> tuple[list[Path], Path]:
    nx, ny, nz = round(3.0 / cell), round(2.0 / cell), 3
    d = tmp_path / "gas"
    d.mkdir(exist_ok=True)
    files = [
        write_gaden(
            d / f"FilamentSimulation_gasType_0_sourcePosition_2.25_-0.95_0.15_iteration_{t}",
            nx,
            ny,
            nz,
            cell,
            scale=1.0 + t,
        )
        for t in range(n_frames)
    ]
    return files, write_obstacles(tmp_path / "occupancy.pgm", 30, 20)


def test_frames_become_a_case_with_steady_mean(tmp_path):
    files, pgm = scenario(tmp_path)
    case = load_gaden(list(reversed(files)), pgm, frame_dt=0.5, release_rate=1.5)
    H, W = 20, 30
    assert case.occupancy.shape == (H, W) and case.resolution == 0.1
    assert case.frames is not None and case.frames.shape == (2, H, W)
    assert case.meta["frame_dt"] == 0.5 and case.meta["solver"] == "gaden"
    assert case.meta["gaden"]["z_index"] == 1  # the slice holding z = 0.15 m
    assert case.meta["release_rate_gps"] == 1.5
    # the source, relative to env_min
    assert case.source == pytest.approx([SOURCE[0] - ENV_MIN[0], SOURCE[1] - ENV_MIN[1]])
    # image row 0 is the top: the block sits at high y, low x
    assert case.occupancy[-5:, :6].all() and case.occupancy[:15, :].sum() == 0
    free = case.free
    conc, u, _, _ = gaden_fields(30, 20, 3, 0.1)
    expect0 = conc[:, :, 1].T  # (ny, nx) of frame 0
    # frames sorted by iteration number; steady field = mean of frames (scale 1 and 2)
    assert np.allclose(case.frames[0][free], expect0[free], atol=1e-5)
    assert np.allclose(case.frames[1][free], 2 * expect0[free], atol=1e-5)
    assert np.allclose(case.concentration[free], 1.5 * expect0[free], atol=1e-5)
    assert np.allclose(case.wind[0][free], u[:, :, 1].T[free], atol=1e-5)
    assert np.allclose(case.wind[1][free], -0.2, atol=1e-6)
    assert (case.wind[:, ~free] == 0).all() and (case.concentration[~free] == 0).all()
    # a GADEN case fits the store and comes back unchanged
    with DatasetStore(tmp_path / "s.h5", "w") as s:
        s.add_layout([case], "test")
        assert cases_equal(s.case(s.layouts()[0], 0), case)


def test_coarser_cells_are_resampled_to_the_grid(tmp_path):
    files, pgm = scenario(tmp_path, cell=0.2, n_frames=1)
    case = load_gaden(files[0], pgm, z_index=0)
    assert case.frames is None and "frame_dt" not in case.meta
    assert case.occupancy.shape == (20, 30)  # 3 x 2 m at 0.1 m
    # the wind's u is linear in y: linear interpolation reproduces it between centres
    y = (np.arange(20) + 0.5) * 0.1
    u_expect = 0.5 + 0.1 * np.clip(y, 0.1, 1.9)
    free = case.free
    assert np.allclose(case.wind[0][free], np.broadcast_to(u_expect[:, None], (20, 30))[free], atol=1e-5)
    # finer GADEN cells are averaged
    (tmp_path / "fine").mkdir()
    files, pgm = scenario(tmp_path / "fine", cell=0.05, n_frames=1)
    fine = load_gaden(files[0], pgm)
    assert fine.occupancy.shape == (20, 30)
    assert np.allclose(fine.wind[1][fine.free], -0.2, atol=1e-6)


def test_read_frame_slices_by_source(tmp_path):
    p = write_gaden(tmp_path / "f", 4, 3, 5, 0.1)
    f = read_gaden_frame(p)
    assert f.z_index == 1  # z = 0.15 m in cells of 0.1 m
    assert f.conc.shape == (3, 4) and f.wind.shape == (2, 3, 4)
    assert f.gas_type == "ethanol" and f.num_cells == (4, 3, 5)


@pytest.mark.parametrize(
    ("override", "kwargs", "match"),
    [
        ({"NumCells_XYZ": None}, {}, "lacks NumCells_XYZ"),
        ({"CellSizes_XYZ[m]": "0.1 0.1"}, {}, "CellSizes_XYZ needs three"),
        ({"env_min(m)": "a b c"}, {}, "env_min needs three"),
        ({"NumCells_XYZ": "4 3 0"}, {}, "must be positive"),
        ({}, {"drop_rows": 2}, "expected 60 rows"),
        ({}, {"unit": "moles"}, "only ppm"),
    ],
)
def test_malformed_files_raise_clear_errors(tmp_path, override, kwargs, match):
    p = write_gaden(tmp_path / "bad", 4, 3, 5, 0.1, header_override=override, **kwargs)
    with pytest.raises(InputDataError, match=match):
        read_gaden_frame(p)


def test_other_problems_raise_clear_errors(tmp_path):
    files, pgm = scenario(tmp_path)
    with pytest.raises(InputDataError, match="frame_dt"):
        load_gaden(files, pgm)
    other = write_gaden(tmp_path / "other_iteration_9", 30, 20, 4, 0.1)
    with pytest.raises(InputDataError, match="differs"):
        load_gaden([files[0], other], pgm, frame_dt=1.0)
    (tmp_path / "junk").write_text("hello world\n1 2 3\n")
    with pytest.raises(InputDataError, match="junk: not a GADEN result file"):
        load_gaden(tmp_path / "junk", pgm)
    wide = write_obstacles(tmp_path / "wide.pgm", 60, 20)
    with pytest.raises(InputDataError, match="square pixels"):
        load_gaden(files[0], wide)
    blocked = tmp_path / "blocked.pgm"
    Image.fromarray(np.zeros((20, 30), np.uint8)).save(blocked)
    with pytest.raises(InputDataError, match="solid cell"):
        load_gaden(files[0], blocked)
    with pytest.raises(InputDataError, match="no such"):
        load_gaden(tmp_path / "missing", pgm)


def test_cli_imports_a_gaden_scenario(tmp_path):
    from dgse.cli.main import main
    from dgse.world.case import Case

    files, pgm = scenario(tmp_path, n_frames=3)
    out = tmp_path / "gaden_case.npz"
    args = ["import-gaden", *map(str, files), "--obstacles", str(pgm), "--frame-dt", "1", "-o", str(out)]
    assert main(args) == 0
    case = Case.load(out)
    assert case.frames.shape == (3, 20, 30) and case.meta["frame_dt"] == 1.0
    missing = str(tmp_path / "none.pgm")
    assert main(["import-gaden", str(files[0]), "--obstacles", missing, "-o", str(out)]) == 2
