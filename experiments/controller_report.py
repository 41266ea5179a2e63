"""Tables and figures of the controller comparison: Markdown/CSV, speed and force over distance against grade
and limits, energy bars per condition. All files are written atomically (temporary file + rename)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from roadload.fileio import save_figure

LABELS = {"cruise": "cruise control (PI)", "human": "human-like driver", "mpc_oracle": "MPC oracle",
          "mpc_abc": "MPC abc (M0)", "mpc_online": "MPC online (M4-RRLM)"}
COLORS = {"cruise": "tab:gray", "human": "tab:brown", "mpc_oracle": "tab:green", "mpc_abc": "tab:red",
          "mpc_online": "tab:blue"}


def write_figures(results: list[dict[str, Any]], table: pd.DataFrame, out: Path) -> list[Path]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    paths = []
    for res in results:
        if "logs" not in res or not res["rows"]:
            continue
        road, cond = res["rows"][0]["road"], res["rows"][0]["condition"]
        if cond not in ("nominal", "drift"):
            continue
        fig, ax = plt.subplots(3, 1, figsize=(11, 8), sharex=True, gridspec_kw={"height_ratios": [3, 2, 1]})
        rd = res["road"]
        ax[0].plot(np.asarray(rd["s"]) / 1000, np.asarray(rd["speed_limit"]) * 3.6, "k--", lw=1, label="speed limit")
        for name, log in res["logs"].items():
            s = log["s"].to_numpy() / 1000
            ax[0].plot(s, log["v"].to_numpy() * 3.6, lw=1.1, color=COLORS.get(name), label=LABELS.get(name, name))
            if name != "human":
                f = (log["traction"] - log["regen"] - log["brake"]).to_numpy() / 1000
                ax[1].plot(s, f, lw=0.8, color=COLORS.get(name), label=LABELS.get(name, name))
        ax[0].set_ylabel("speed [km/h]")
        ax[0].legend(fontsize=7, ncol=3, loc="lower center")
        ax[1].set_ylabel("wheel force [kN]")
        ax[1].axhline(0, color="k", lw=0.5)
        ax[2].plot(np.asarray(rd["s"]) / 1000, np.asarray(rd["elevation"]), color="tab:olive")
        ax2 = ax[2].twinx()
        ax2.plot(np.asarray(rd["s"]) / 1000, np.tan(np.asarray(rd["grade"])) * 100, color="tab:purple", lw=0.6)
        ax2.set_ylabel("grade [%]", color="tab:purple")
        ax[2].set_ylabel("elevation [m]")
        ax[2].set_xlabel("distance [km]")
        fig.suptitle(f"{road} / {cond}: speed and wheel force over distance")
        fig.tight_layout()
        path = out / f"speed_force_{road}_{cond}.png"
        save_figure(fig, path, dpi=110)
        paths.append(path)
    if len(table):
        t = table.copy()
        t["who"] = np.where(t.controller == "mpc", "mpc_" + t.force_model.astype(str), t.controller)
        for road, g in t.groupby("road", sort=False):
            conds = list(dict.fromkeys(g.condition))
            whos = [w for w in LABELS if w in set(g.who)]
            fig, ax = plt.subplots(figsize=(11, 4.5))
            width = 0.8 / max(len(whos), 1)
            for i, w in enumerate(whos):
                vals, hatch = [], []
                for c in conds:
                    r = g[(g.condition == c) & (g.who == w)]
                    vals.append(float(r.energy_kWh.iloc[0]) if len(r) else np.nan)
                    hatch.append("//" if len(r) and not bool(r.matched.iloc[0]) else "")
                x = np.arange(len(conds)) + (i - (len(whos) - 1) / 2) * width
                bars = ax.bar(x, vals, width, color=COLORS.get(w), label=LABELS.get(w, w))
                for b, h in zip(bars, hatch):
                    b.set_hatch(h)
            ax.set_xticks(np.arange(len(conds)), conds)
            ax.set_ylabel("source energy [kWh]")
            ax.set_title(f"{road}: energy per condition (hatched: trip time not matched to cruise within tolerance)")
            ax.legend(fontsize=8, ncol=5)
            fig.tight_layout()
            path = out / f"energy_bars_{road}.png"
            save_figure(fig, path, dpi=110)
            paths.append(path)
    return paths
