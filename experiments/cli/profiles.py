"""``roadload profiles ...``: list the named profiles, show a profile's statistics, export one to JSON/CSV.

Light at import (see the package docstring): the road generators (numba, scipy) load inside the commands."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import typer

if TYPE_CHECKING:
    from roadload.road_profiles.profile import DriveCycle, RoadProfile


def profile_summary(profile: RoadProfile | DriveCycle) -> dict[str, float | int | str]:
    """Key statistics of a profile or cycle in edge units (km, %, km/h) for display."""
    from roadload.road_profiles.profile import DriveCycle

    if isinstance(profile, DriveCycle):
        out: dict[str, float | int | str] = {
            "kind": "drive cycle", "duration_s": profile.duration, "distance_km": profile.distance / 1000,
            "v_max_kmh": float(profile.speed.max() * 3.6), "v_mean_kmh": profile.distance / profile.duration * 3.6}
        if profile.grade is not None:
            out["grade_min_pct"] = float(np.tan(profile.grade).min() * 100)
            out["grade_max_pct"] = float(np.tan(profile.grade).max() * 100)
        return out
    kappa = np.abs(profile.curvature)
    return {"kind": "road profile", "length_km": profile.length / 1000,
            "grade_min_pct": float(np.tan(profile.grade).min() * 100),
            "grade_max_pct": float(np.tan(profile.grade).max() * 100),
            "grade_std_pct": float(np.tan(profile.grade).std() * 100),
            "elevation_range_m": float(np.ptp(profile.elevation())),
            "min_radius_m": float(1 / kappa.max()) if kappa.max() > 0 else float("inf"),
            "bank_max_deg": float(np.degrees(np.abs(profile.bank).max())),
            "speed_limits_kmh": " ".join(f"{v:g}" for v in np.unique(np.round(profile.speed_limit * 3.6))),
            "stops": int(profile.stops.size),
            "stops_per_km": profile.stops.size / (profile.length / 1000)}


def register(app: typer.Typer, benchmark_app: typer.Typer) -> None:
    profiles = typer.Typer(help="Road profiles and drive cycles: list, show, export.", no_args_is_help=True)
    app.add_typer(profiles, name="profiles")

    @profiles.command("list")
    def list_profiles(kind: str = typer.Option(None, help="only 'road' or 'cycle'")) -> None:
        """List the registered profile names."""
        if kind not in (None, "road", "cycle"):
            raise typer.BadParameter(f"must be 'road' or 'cycle', got {kind!r}", param_hint="--kind")
        from rich.console import Console
        from rich.table import Table

        from roadload.road_profiles.registry import known_profiles

        table = Table("name", "description")
        for name, description in known_profiles(kind).items():
            table.add_row(name, description)
        Console().print(table)

    @profiles.command("show")
    def show(name: str = typer.Argument(..., help="profile name or .json/.csv/.gpx file"),
             seed: int = typer.Option(0, help="seed of generated profiles")) -> None:
        """Print a profile's statistics (length, grade, radii, limits, stops)."""
        from rich.console import Console
        from rich.table import Table

        from roadload.road_profiles.registry import load_profile

        profile = load_profile(name, seed=seed)
        table = Table("quantity", "value", title=f"{profile.name} ({profile.meta.get('licence', 'no licence')})")
        for key, value in profile_summary(profile).items():
            table.add_row(key, f"{value:.4g}" if isinstance(value, float) else str(value))
        Console().print(table)

    @profiles.command("export")
    def export(name: str = typer.Argument(..., help="profile name or file"),
               out: Path = typer.Argument(..., help="output .json or .csv"),
               seed: int = typer.Option(0, help="seed of generated profiles")) -> None:
        """Write a named profile to a JSON or CSV file (SI units, meta with source and licence)."""
        from roadload.road_profiles.files import save_profile
        from roadload.road_profiles.registry import load_profile

        path = save_profile(load_profile(name, seed=seed), out)
        typer.echo(f"wrote {path}")
