"""A small GADEN scenario folder written on demand (map, STL outlets, settings, scene, CFD wind CSV).

:func:`write_gaden_scenario` lays out what GADEN's tools write for a 4 x 3 m
building in the map frame (origin ``ORIGIN``): ``occupancy.yaml`` +
``occupancy.pgm`` (plain PGM, maxval 1, as ``gaden_preprocessing`` prints it,
0.02 m pixels), ``cad_models/door_west.stl`` (ASCII) and
``cad_models/door_east.stl`` (binary) listed under ``outlets_models`` of
``environment_configurations/config1/config.yaml``, the simulation
``.../simulations/sim1/sim.yaml`` (``source: position``), a BasicSim scene
``scene.yaml`` (``robots: position``) and two time steps of
``wind_simulations/1ms/wind_at_cell_centers_<t>.csv``.  Grid-frame facts the
tests check are the module's constants.  The models and the wind are written by the
package's writers (:func:`dgse.data.gaden_scenario.write_stl`, ``write_wind_csv``); the map
and the settings here in forms the package's export does not write (a plain PGM at 0.02 m
pixels, a colour entry among the listed models, a wind that turns above the sensors).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from dgse.data.gaden_scenario import box_triangles, write_stl, write_wind_csv

#: Map-frame position of the map's lower-left corner, m.
ORIGIN = (-1.0, -0.5)
#: The building, m (grid frame).
WIDTH, HEIGHT, WALL, PIXEL = 4.0, 3.0, 0.1, 0.02
#: Door spans along their side (grid frame, m): the west door lets air in, the east one out.
WEST_DOOR, EAST_DOOR = (1.8, 2.4), (0.4, 1.0)
#: An interior wall at x = 2.0..2.1 m with a door at y = 1.0..2.0 m.
INNER_WALL, INNER_DOOR = (2.0, 2.1), (1.0, 2.0)
#: Grid-frame source and start, m; the source's height, m.
SOURCE, START, SOURCE_Z = (3.0, 2.2), (0.75, 0.75), 0.5
#: Mean west-to-east wind at the sensors' height over the two time steps, m/s; above 0.8 m it blows back.
WIND_U, WIND_ABOVE = 0.4, -3.0


def occupancy(pixel: float = PIXEL) -> np.ndarray:
    """Solid mask ``(rows, cols)`` at ``pixel`` m, row 0 at the bottom (grid frame)."""
    ny, nx = round(HEIGHT / pixel), round(WIDTH / pixel)
    y, x = (np.arange(ny) + 0.5) * pixel, (np.arange(nx) + 0.5) * pixel
    X, Y = np.meshgrid(x, y)
    solid = (X < WALL) | (X > WIDTH - WALL) | (Y < WALL) | (Y > HEIGHT - WALL)
    solid |= (X > INNER_WALL[0]) & (X < INNER_WALL[1]) & ~((Y > INNER_DOOR[0]) & (Y < INNER_DOOR[1]))
    solid &= ~((X < WALL) & (Y > WEST_DOOR[0]) & (Y < WEST_DOOR[1]))
    solid &= ~((X > WIDTH - WALL) & (Y > EAST_DOOR[0]) & (Y < EAST_DOOR[1]))
    return solid


def write_gaden_scenario(
    root: Path,
    *,
    seed: int = 0,
    with_map: bool = True,
    west_door_shift: tuple[float, float] = (0.0, 0.0),
    source: tuple[float, float] = SOURCE,
    with_wind: bool = True,
) -> Path:
    """Write the scenario folder ``root`` (module docstring) and return it.

    ``west_door_shift`` moves the west door's model (m, e.g. off the map);
    ``source`` is the grid-frame source written to the simulation file.
    """
    rng = np.random.default_rng(seed)
    ox, oy = ORIGIN
    root.mkdir(parents=True, exist_ok=True)
    if with_map:
        solid = occupancy()
        rows = np.flipud(np.where(solid, 0, 1))  # image row 0 = north; 1 free, 0 occupied
        body = "\n".join(" ".join(str(v) for v in r) for r in rows)
        (root / "occupancy.pgm").write_text(f"P2\n{rows.shape[1]} {rows.shape[0]}\n1\n{body}\n")
        (root / "occupancy.yaml").write_text(
            f"image: occupancy.pgm\nresolution: {PIXEL}\norigin: [{ox}, {oy}, 0.0]\n"
            "occupied_thresh: 0.9\nfree_thresh: 0.1\nnegate: 0\n"
        )
    cad = root / "cad_models"
    cad.mkdir(exist_ok=True)
    dx, dy = west_door_shift
    write_stl(
        cad / "door_west.stl",
        box_triangles(ox + dx, ox + WALL + dx, oy + WEST_DOOR[0] + dy, oy + WEST_DOOR[1] + dy, 0.0, 2.0),
    )
    write_stl(
        cad / "door_east.stl",
        box_triangles(ox + WIDTH - WALL, ox + WIDTH, oy + EAST_DOOR[0], oy + EAST_DOOR[1], 0.0, 2.0),
        binary=True,
    )
    config = root / "environment_configurations" / "config1"
    (config / "simulations" / "sim1").mkdir(parents=True, exist_ok=True)
    (config / "config.yaml").write_text(
        "models:\n  - ../../cad_models/walls.stl\noutlets_models:\n"
        '  - "!color [0.86, 0.24, 0.24, 1.00]"\n'
        "  - ../../cad_models/door_west.stl\n  - ../../cad_models/door_east.stl\n"
        "unprocessed_wind_files: ../../wind_simulations/1ms/wind_at_cell_centers\n"
        "cell_size: 0.1\n"
    )
    sx, sy = source
    (config / "simulations" / "sim1" / "sim.yaml").write_text(
        f"source:\n  sourceType: point\n  position: [{sx + ox}, {sy + oy}, {SOURCE_Z}]\n  gasType: 0\n"
        "deltaTime: 0.1\n"
    )
    (root / "scene.yaml").write_text(
        f'map: "occupancy.yaml"\nrobots:\n  - name: "PioneerP3DX"\n'
        f"    position: [{START[0] + ox}, {START[1] + oy}, 0.0]\n    angle: 1\n"
    )
    if with_wind:
        wind_dir = root / "wind_simulations" / "1ms"
        wind_dir.mkdir(parents=True, exist_ok=True)
        step = 0.1
        xs = np.arange(WALL + step / 2, WIDTH - WALL, step)
        ys = np.arange(WALL + step / 2, HEIGHT - WALL, step)
        zs = np.array([0.45, 0.55, 1.05])
        X, Y, Z = (a.reshape(-1) for a in np.meshgrid(xs, ys, zs))
        for t, u_mean in enumerate((WIND_U - 0.1, WIND_U + 0.1)):
            u = np.where(Z < 0.8, u_mean, WIND_ABOVE) + rng.normal(0.0, 0.01, X.size)
            v = rng.normal(0.0, 0.01, X.size)
            points = np.column_stack([X + ox, Y + oy, Z])
            write_wind_csv(
                wind_dir / f"wind_at_cell_centers_{t}.csv", points, np.column_stack([u, v, np.zeros(X.size)])
            )
    return root
