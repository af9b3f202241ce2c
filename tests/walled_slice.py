"""A closed, GADEN-like scenario made here: a built-in solve with walls drawn at the map's edge.

The solve's inlet and outlet become walls; the air that crossed them now enters
and leaves through the slice (the wind's divergence in the cells beside them),
as in a z slice of a 3-D GADEN flow.  The case is written as a GADEN ASCII
snapshot and an obstacle image, for ``dgse import-gaden``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from PIL import Image

from dgse.bench.scenarios import walled_case
from dgse.world.case import Case


def walled_fields(case: Case) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(occupancy, wind, concentration)`` of ``case`` with every edge cell solid (0 wind and gas there)."""
    walled = walled_case(case)
    return walled.occupancy, walled.wind.astype(np.float64), walled.concentration


def write_gaden_slice(case: Case, folder: Path) -> tuple[Path, Path]:
    """The walled ``case`` as one GADEN snapshot (one z layer of 0.1 m) and its obstacle PGM."""
    occ, wind, conc = walled_fields(case)
    H, W = occ.shape
    h = case.resolution
    x, y = case.source
    folder.mkdir(parents=True, exist_ok=True)
    lines = [
        "env_min(m) 0.0000 0.0000 0.0000",
        f"env_max(m) {W * h:.4f} {H * h:.4f} {h:.4f}",
        f"NumCells_XYZ {W} {H} 1",
        f"CellSizes_XYZ[m] {h:.4f} {h:.4f} {h:.4f}",
        f"GasSourceLocation_XYZ[m] {x:.4f} {y:.4f} {0.5 * h:.4f}",
        "Cell_x\t Cell_y\t Cell_z\t Gas_conc[ppm]\t Wind_u[m/s]\t Wind_v[m/s]\t Wind_w[m/s]",
    ]
    lines += [
        f"{j} {i} 0 {conc[i, j]:.6f} {wind[0, i, j]:.6f} {wind[1, i, j]:.6f} 0.000000"
        for i in range(H)
        for j in range(W)
    ]
    snapshot = folder / f"FilamentSimulation_gasType_0_sourcePosition_{x:.2f}_{y:.2f}_0.05_iteration_0"
    snapshot.write_text("\n".join(lines) + "\n")
    image = np.where(occ[::-1] != 0, 0, 255).astype(np.uint8)  # row 0 at the top, dark = solid
    pgm = folder / "occupancy.pgm"
    Image.fromarray(image).save(pgm)
    return snapshot, pgm
