"""``fgloc map-info MAP.yaml``: load a map_server map and describe it."""

from __future__ import annotations

from pathlib import Path

import typer


def map_info(map_yaml: Path = typer.Argument(..., help="map_server YAML file")) -> None:
    """Load a map_server map (YAML + PGM/PNG) and print its size, origin and cell counts."""
    from fgloc.maps import load_map  # numba and scipy load only for this command, not for every `fgloc ...`

    m = load_map(map_yaml)
    xmin, xmax, ymin, ymax = m.extent
    print(f"{map_yaml}: {m.width} x {m.height} cells at {m.resolution:g} m "
          f"({xmax - xmin:.2f} m x {ymax - ymin:.2f} m), origin "
          f"[{m.origin[0]:g}, {m.origin[1]:g}, {m.origin[2]:g}], mode {m.mode}")
    print(f"occupied {int(m.occupied.sum())}, free {int(m.free.sum())}, unknown {int(m.unknown.sum())} cells")


def register(app: typer.Typer) -> None:
    app.command("map-info")(map_info)
