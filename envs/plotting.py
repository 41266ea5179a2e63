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


def _speed_panel(ax, trip: Trip, km: np.ndarray, km_t: np.ndarray | None) -> None:
    """Measured and true speed [km/h]."""
    if trip.has("vehicle_speed"):
        ax.plot(km, trip.channel("vehicle_speed") * 3.6, lw=0.6, label="vehicle_speed (measured)")
    if trip.truth is not None:
        ax.plot(km_t, trip.truth["speed"] * 3.6, lw=0.8, label="speed (truth)")
    ax.set_ylabel("speed [km/h]")
    ax.legend(loc="upper right", fontsize=8)


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
    ax.legend(loc="upper right", fontsize=8, ncol=3)


def _grade_panel(ax, trip: Trip, km: np.ndarray, km_t: np.ndarray | None) -> None:
    """True grade and accel_x / g [%], with the elevation [m] on a second axis."""
    tr = trip.truth
    if tr is not None and "grade" in tr:
        ax.plot(km_t, np.tan(tr["grade"]) * 100.0, lw=0.8, label="grade (truth)")
    if trip.has("accel_x"):
        ax.plot(km, trip.channel("accel_x") / G * 100.0, lw=0.3, alpha=0.5, label="accel_x / g")
    ax.set_ylabel("grade [%]")
    ax.legend(loc="upper left", fontsize=8)
    if tr is not None and "elevation" in tr:
        x, elev = km_t, tr["elevation"].to_numpy()
    elif trip.has("elevation"):
        x, elev = km, trip.channel("elevation")
    else:
        return
    ax2 = ax.twinx()
    ax2.plot(x, elev, color="0.4", lw=0.8)
    ax2.set_ylabel("elevation [m]")


def _parameter_panel(ax, trip: Trip, km: np.ndarray, km_t: np.ndarray | None) -> None:
    """Relative change [%] of the drifting true parameters, or the measured gear and clutch of a real log."""
    tr = trip.truth
    if tr is None:
        for name in ("gear", "clutch"):
            if trip.has(name):
                ax.plot(km, trip.channel(name), lw=0.6, label=name)
        ax.legend(loc="upper right", fontsize=8)
        return
    for name in ("mass", "rolling_resistance_f0", "drag_area", "air_density", "brake_friction_coefficient",
                 "drivetrain_loss_factor", "cornering_stiffness"):
        if name in tr:
            x = tr[name].to_numpy()
            ref = x[0] if x[0] != 0 else 1.0
            ax.plot(km_t, (x / ref - 1.0) * 100.0, lw=0.8, label=name)
    ax.set_ylabel("parameter change [%]")
    ax.legend(loc="upper right", fontsize=8, ncol=2)


def plot_trip(trip: Trip, out: str | os.PathLike) -> Path:
    """Write a PNG (4 panels over distance [km]: speed, forces, grade / elevation, drifting parameters) and return
    its path; written atomically."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out = Path(out)
    if out.suffix.lower() != ".png":
        raise ValueError(f"plot output must end in .png, got {out.name!r}")
    d_meas, d_truth = _distance(trip)
    km, km_t = d_meas / 1000.0, None if d_truth is None else d_truth / 1000.0
    fig, axes = plt.subplots(4, 1, figsize=(11, 11), sharex=True)
    for ax, panel in zip(axes, (_speed_panel, _force_panel, _grade_panel, _parameter_panel)):
        panel(ax, trip, km, km_t)
    axes[-1].set_xlabel("distance [km]")
    title = trip.meta.get("name", "trip")
    if trip.meta.get("source") == "sim":
        title += f"  (effects: {', '.join(trip.meta.get('effects', {}).get('effects', {})) or 'none'})"
    fig.suptitle("\n".join(textwrap.wrap(title, 130)), fontsize=9)
    fig.tight_layout()
    save_figure(fig, out, dpi=90)
    return out
