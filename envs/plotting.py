"""Overview figure of a Trip over distance: speed, forces, grade / elevation and the drifting parameters."""

from __future__ import annotations

from roadload.units import G

import os
import textwrap
from pathlib import Path

import numpy as np

from roadload.trip import Trip
from roadload.fileio import save_figure


def _distance(trip: Trip) -> tuple[np.ndarray, np.ndarray | None]:
    """Distance [m] of the measured samples (and of the truth samples, if any)."""
    if trip.truth is not None and "position" in trip.truth:
        d_truth = trip.truth["position"].to_numpy()
        return np.interp(trip.t, trip.truth["t"].to_numpy(), d_truth), d_truth
    if "distance" in trip.measured:
        return trip.channel("distance"), None
    v = np.nan_to_num(trip.channel("vehicle_speed")) if trip.has("vehicle_speed") else np.zeros(len(trip))
    t = trip.t
    return np.concatenate([[0.0], np.cumsum(0.5 * (v[1:] + v[:-1]) * np.diff(t))]), None


#: truth parameters the last panel shows when they drift (relative change along the trip)
DRIFTING_PARAMETERS = ("mass", "rolling_resistance_f0", "drag_area", "air_density", "brake_friction_coefficient",
                       "drivetrain_loss_factor", "cornering_stiffness")


def drifting_parameters(trip: Trip, rtol: float = 1e-6) -> dict[str, np.ndarray]:
    """Truth parameters that change along the trip by more than ``rtol`` (relative), as change [%] from their first
    value: what the last panel of :func:`plot_trip` shows (none when no drifting effect is on)."""
    out: dict[str, np.ndarray] = {}
    tr = trip.truth
    for name in DRIFTING_PARAMETERS:
        if tr is None or name not in tr:
            continue
        x = tr[name].to_numpy(dtype=float)
        ref = x[0] if x[0] != 0 else 1.0
        change = (x / ref - 1.0) * 100.0
        if np.nanmax(np.abs(change)) > rtol * 100.0:
            out[name] = change
    return out


def energy_summary(trip: Trip, distance_m: float) -> str:
    """One line: duration, distance and the source energy (battery kWh/100 km or fuel l/100 km at 32 MJ/l) from a
    simulated trip's energy ledger; without a ledger, duration and distance only."""
    text = f"{trip.duration:.0f} s, {distance_m / 1000.0:.2f} km"
    energy = (trip.meta.get("energy") or {}).get("source") if isinstance(trip.meta.get("energy"), dict) else None
    if energy is None or distance_m <= 0:
        return text
    vehicle = trip.meta.get("vehicle")
    drivetrain = vehicle.get("drivetrain") if isinstance(vehicle, dict) else None
    kind = drivetrain.get("kind") if isinstance(drivetrain, dict) else None
    per_100km = energy / distance_m * 1e5
    if kind == "bev":
        return f"{text}, battery energy {energy / 3.6e6:.2f} kWh ({per_100km / 3.6e6:.1f} kWh/100 km)"
    return f"{text}, fuel energy {energy / 3.6e6:.2f} kWh ({per_100km / 32.0e6:.1f} l/100 km at 32 MJ/l)"


#: legends beside the axes, never over the traces
LEGEND = {"loc": "upper left", "bbox_to_anchor": (1.01, 1.0), "fontsize": 8, "borderaxespad": 0.0}


def _speed_panel(ax, trip: Trip, km: np.ndarray, km_t: np.ndarray | None) -> None:
    """Measured and true speed [km/h]."""
    if trip.has("vehicle_speed"):
        ax.plot(km, trip.channel("vehicle_speed") * 3.6, lw=0.6, label="vehicle_speed (measured)")
    if trip.truth is not None:
        ax.plot(km_t, trip.truth["speed"] * 3.6, lw=0.8, label="speed (truth)")
    ax.set_ylabel("speed [km/h]")
    ax.legend(**LEGEND)


def _force_panel(ax, trip: Trip, km: np.ndarray, km_t: np.ndarray | None) -> None:
    """True tractive force and driving resistances [kN], or the measured drive torque [N m] of a real log."""
    tr = trip.truth
    if tr is not None:
        for name, label in (("tractive_force", "tractive force F_xV"), ("rolling_resistance_force", "rolling"),
                            ("aero_force", "aero"), ("climbing_force", "climbing"), ("brake_force", "brakes")):
            if name in tr:
                ax.plot(km_t, tr[name] / 1000.0, lw=0.6, label=label)
        ax.set_ylabel("force [kN]")
    elif trip.has("drive_torque"):
        ax.plot(km, trip.channel("drive_torque"), lw=0.6, label="drive_torque")
        ax.set_ylabel("torque [N m]")
    if ax.lines:
        ax.legend(**LEGEND)


def _grade_panel(ax, trip: Trip, km: np.ndarray, km_t: np.ndarray | None) -> None:
    """True grade and accel_x / g [%], with the elevation [m] on a second axis (in the same legend)."""
    tr = trip.truth
    if tr is not None and "grade" in tr:
        ax.plot(km_t, np.tan(tr["grade"]) * 100.0, lw=0.8, label="grade (truth)")
    if trip.has("accel_x"):
        ax.plot(km, trip.channel("accel_x") / G * 100.0, lw=0.3, alpha=0.5, label="accel_x / g")
    ax.set_ylabel("grade [%]")
    handles, labels = ax.get_legend_handles_labels()
    if tr is not None and "elevation" in tr:
        x, elev = km_t, tr["elevation"].to_numpy()
    elif trip.has("elevation"):
        x, elev = km, trip.channel("elevation")
    else:
        x, elev = None, None
    if elev is not None:
        ax2 = ax.twinx()
        line, = ax2.plot(x, elev, color="0.4", lw=0.8)
        ax2.set_ylabel("elevation [m]")
        handles, labels = handles + [line], labels + ["elevation (right axis)"]
    if handles:
        ax.legend(handles, labels, **{**LEGEND, "bbox_to_anchor": (1.07, 1.0)})


def _parameter_panel(ax, trip: Trip, km: np.ndarray, km_t: np.ndarray | None) -> None:
    """Relative change [%] of the drifting true parameters, or the measured gear and clutch of a real log."""
    if trip.truth is None:
        for name in ("gear", "clutch"):
            if trip.has(name):
                ax.plot(km, trip.channel(name), lw=0.6, label=name)
    else:
        for name, change in drifting_parameters(trip).items():
            ax.plot(km_t, change, lw=0.8, label=name)
        ax.set_ylabel("parameter change [%]")
    if ax.lines:
        ax.legend(**LEGEND)


def plot_trip(trip: Trip, out: str | os.PathLike) -> Path:
    """Write a PNG over distance [km] and return its path (written atomically): speed, forces (or drive torque),
    grade with elevation, and -- when a drifting effect is on -- the parameters' change; the title carries the
    effects and the energy summary. Legends sit beside the axes, never over the traces."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out = Path(out)
    if out.suffix.lower() != ".png":
        raise ValueError(f"plot output must end in .png, got {out.name!r}")
    d_meas, d_truth = _distance(trip)
    km, km_t = d_meas / 1000.0, None if d_truth is None else d_truth / 1000.0
    drifting = drifting_parameters(trip) if trip.truth is not None else {}
    panels = [_speed_panel, _force_panel, _grade_panel]
    if drifting or trip.truth is None:
        panels.append(_parameter_panel)
    fig, axes = plt.subplots(len(panels), 1, figsize=(12, 2.7 * len(panels) + 0.8), sharex=True)
    for ax, panel in zip(axes, panels):
        panel(ax, trip, km, km_t)
    axes[-1].set_xlabel("distance [km]")
    title = trip.meta.get("name", "trip")
    if trip.meta.get("source") == "sim":
        title += f"  (effects: {', '.join(trip.meta.get('effects', {}).get('effects', {})) or 'none'}"
        title += ")" if drifting else "; no parameter drifts)"
    d = d_truth if d_truth is not None and d_truth.size else d_meas
    distance = float(d[-1] - d[0]) if d.size else 0.0
    title += "\n" + energy_summary(trip, distance)
    fig.suptitle("\n".join(textwrap.fill(line, 130) for line in title.split("\n")), fontsize=9)
    fig.tight_layout()
    save_figure(fig, out, dpi=90)
    return out
