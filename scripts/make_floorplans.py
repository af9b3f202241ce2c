"""Two generated office floors as ROS map_server maps, for the floor plan import at building scale.

Writes ``benchmarks/floorplans/office-3.{yaml,pgm}`` (21.7 x 24.7 m, one
corridor) and ``office-6.{yaml,pgm}`` (30.8 x 26.9 m, two corridors joined by
two connectors), made by :func:`dgse.world.building.random_office_floor` with
seeds 3 and 6 at 0.1 m (one pixel per cell) by
:func:`dgse.world.floorplan.export_ros_map`.  Each map is read back the way
``dgse import-floorplan`` reads it (``load_ros_map`` + ``layout_from_floorplan``
with the generated openings) and must give the same occupancy, walls and
openings.  The ROS format carries no openings: the YAML lists them in comments,
and the command printed for each map imports it with one inlet and one outlet
(the CLI takes one of each)::

    python scripts/make_floorplans.py
    dgse import-floorplan benchmarks/floorplans/office-3.yaml --inlet west 9.4 10.3 \\
        --outlet east 13.3 14.5 -o office-3.npz
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from dgse.world.building import random_office_floor
from dgse.world.floorplan import export_ros_map, layout_from_floorplan, load_ros_map
from dgse.world.layout import Layout

SEEDS = (3, 6)


def round_trip(layout: Layout, yaml_path: Path) -> Layout:
    """The layout imported back from its ROS map, with its own openings; raises if it differs."""
    back = layout_from_floorplan(
        load_ros_map(yaml_path, layout.resolution), None, layout.inlets, layout.outlets, name=layout.name
    )
    if not np.array_equal(back.occupancy, layout.occupancy) or back.walls != layout.walls:
        raise SystemExit(f"{yaml_path}: the imported occupancy differs from the generated one")
    return back


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument(
        "-o", "--out", type=Path, default=Path(__file__).resolve().parents[1] / "benchmarks" / "floorplans"
    )
    args = ap.parse_args()
    for seed in SEEDS:
        layout = random_office_floor(seed)
        yaml_path, pgm_path = export_ros_map(layout, args.out / layout.name)
        round_trip(layout, yaml_path)
        h, w = layout.occupancy.shape
        i, o = layout.inlets[0], layout.outlets[0]
        size = pgm_path.stat().st_size
        print(f"{yaml_path} + {pgm_path.name}: {w} x {h} cells, {size} bytes; imports back")
        print(
            f"  dgse import-floorplan {yaml_path} --inlet {i.side} {i.start_m:g} {i.end_m:g} "
            f"--outlet {o.side} {o.start_m:g} {o.end_m:g} -o {layout.name}.npz"
        )


if __name__ == "__main__":
    main()
