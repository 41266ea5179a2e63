"""The least energy any drive could use on ``roadload/EcoTraffic-v0``'s held-out episodes at the IDM follower's
speed: how much a policy can still win against the follower, per episode, in the same model.

    python scripts/traffic_limit.py --episodes 50      # ~2 min CPU
    python scripts/traffic_limit.py --quick            # CI smoke run (2 short episodes)

Per held-out episode (the PPO evaluation's: episode and road seed 50000 + k, safety layer on, spawn outside the
envelope) the follower is driven on the native env and its trip recorded: distance D [m], trip time T [s] (the
40 s episode), start and end speed, speed over distance, and the position of the vehicle ahead on its lane over
time. On the full-route optimum's grid (roadload.controllers.optimum, 5 m segments over [0, D] of the ego's own
road, grade and curvature; the i3's source-energy model and its true road-load parameters) two drives are solved
and compared with the follower's own drive evaluated in the same model:

- **the limit with the traffic relaxed**: the least model source energy over [0, D] in time T from the follower's
  start speed to its end speed (``terminal='speed'``): the same trip, same mean speed, same kinetic energy left;
- **the limit behind the traffic**: the same with the vehicles ahead as a hard wall, t(s) >= T_lb(s), T_lb the first
  time the vehicle ahead on the lane (its rear, less ``min_gap``) has passed s for good (the earliest time the ego
  may be at s without ever closing below ``min_gap``; the follower's drive satisfies it, the running minimum over
  the future makes a cut-in count from the start). The bound is lowered wherever the grid would make the follower's
  own drive infeasible (its node times come from the grid's trapezoid), so the follower is always a feasible drive.

The comfort limits of the optimum are relaxed so that the follower's own drive is inside them (no jerk limit,
acceleration within ``accel_max``, deceleration within ``decel_max``): every difference is energy a drive at the
follower's speed could save, not a difference of comfort. The follower's model energy is its speed over distance on
the same grid, the wheel force from the model's dynamics, regeneration first up to the drive's limits, the friction
brake for the rest. The model against the plant is reported as the follower's plant energy less its model energy.

Headroom = follower's model energy - limit, in Wh/km of D, per episode; mean and 95 % t-interval over episodes.
"""

from __future__ import annotations

import argparse
import math
import time
from dataclasses import dataclass
from typing import Any

import casadi as ca
import numpy as np
import pandas as pd

from roadload.controllers.optimum import FullRouteOptimum, OptimumSettings
from roadload.controllers.vehicle_models import energy_model_from_spec, oracle_parameters
from roadload.gym.config import EcoTrafficConfig, make_config
from roadload.gym.traffic import EcoTrafficEnv
from roadload.gym.traffic_ego import ego_road
from roadload.presets import get_preset
from roadload.tables import markdown_table

from .common import RLError, json_object_option
from .highway import idm_policy
from .traffic_training import TRAFFIC_HELD_OUT, TRAFFIC_TRAIN_CONFIG

LIMIT_SETTINGS = OptimumSettings(ds=5.0, accel_max=4.0, decel_max=6.0, jerk=False, speed_margin=0.0,
                                 speed_floor=1.0, tol=1e-7)
"""The optimum's grid and relaxed comfort limits (module docstring): 5 m segments, |a| up to 4 / 6 m/s^2, no jerk
limit, no margin under the speed limit."""
MIN_GAP = 2.0
"""Bumper-to-bumper gap [m] the limit behind the traffic keeps to the vehicle ahead (the safety layer's margin)."""


@dataclass
class FollowerTrip:
    """One recorded held-out episode of the follower: per step end time t [s], distance s [m], speed v [m/s],
    bumper-to-bumper gap to the vehicle ahead [m] (inf: none), and the plant's source energy [J]."""

    seed: int
    t: np.ndarray
    s: np.ndarray
    v: np.ndarray
    gap: np.ndarray
    energy_J: float
    crashed: bool


def record_follower(env: EcoTrafficEnv, policy, seed: int) -> FollowerTrip:
    """The follower's episode ``seed`` (episode and road seed) with its speed, distance and the gap ahead."""
    obs, info = env.reset(seed=int(seed), options={"road_seed": int(seed)})
    e0 = info["source_energy_total"]
    rows = [(info["t"], info["s"], info["speed"], info["front_gap"])]
    done = False
    while not done:
        obs, _, terminated, truncated, info = env.step(policy(obs))
        rows.append((info["t"], info["s"], info["speed"], info["front_gap"]))
        done = terminated or truncated
    t, s, v, gap = (np.asarray(c, float) for c in zip(*rows))
    gap = np.where(np.isfinite(gap) & (gap < 1e6), gap, np.inf)
    return FollowerTrip(int(seed), t, s, v, gap, float(info["source_energy_total"] - e0), bool(info["crashed"]))


def earliest_times(trip: FollowerTrip, nodes: np.ndarray, min_gap: float) -> np.ndarray:
    """T_lb at each node [s] (module docstring): the wall B(t) = s(t) + gap(t) - min_gap, its running minimum over
    the future (a vehicle that cuts in later bounds every earlier time too), and the first time it reaches each
    node (0 before the wall binds, the trip time where it never does)."""
    wall = trip.s + trip.gap - min_gap
    wall = np.minimum.accumulate(wall[::-1])[::-1]
    k = np.searchsorted(wall, nodes, side="left")  # wall is non-decreasing
    return np.where(k < wall.size, trip.t[np.minimum(k, wall.size - 1)], trip.t[-1])


class GapLimitedOcp:
    """The optimum's NLP (the same formulation as roadload.controllers.optimum.TimedOcp, objective the source
    energy) with lower bounds on the time at every node: t_k >= T_lb(s_k)."""

    def __init__(self, opt: FullRouteOptimum) -> None:
        self.ocp = opt.ocp
        f = self.ocp._formulate()
        x, p, g = f["x"], f["p"], f["g"]
        n = self.ocp.n
        v = ca.sqrt(2.0 * x[:n + 1])
        ds = p[p.numel() - n:]
        t_nodes = ca.cumsum(ds / (0.5 * (v[:-1] + v[1:])))
        nlp = {"x": x, "p": p, "f": f["energy"] + f["regularisation"], "g": ca.vertcat(g, f["t_end"], t_nodes)}
        opts: dict[str, Any] = {"expand": True, "print_time": False, "error_on_fail": False,
                                "ipopt": {"print_level": 0, "sb": "yes", "max_iter": 3000, "tol": 1e-7,
                                          "mu_strategy": "adaptive"}}
        self.solver = ca.nlpsol("gap_limited", "ipopt", nlp, opts)
        self.energy_fun = ca.Function("energy", [x, p], [f["energy"] * 1000.0])

    def solve(self, opt: FullRouteOptimum, params, v0: float, v_end: float, model_time: float,
              t_lb: np.ndarray, x0: np.ndarray) -> tuple[float, bool]:
        """(model source energy [J], success) of the fastest-to-arrive-no-earlier drive."""
        ocp, n = self.ocp, self.ocp.n
        lbx, ubx, lbg, ubg = ocp._bounds(v0, opt.preview, params)
        lbg[2 * n:3 * n], ubg[2 * n:3 * n] = -np.inf, np.inf  # no jerk limit
        lbx[n] = ubx[n] = 0.5 * v_end ** 2
        lbg = np.concatenate([lbg, [model_time], t_lb])
        ubg = np.concatenate([ubg, [model_time], np.full(n, np.inf)])
        p = ocp._params(0.0, opt.preview, params, 0.0)
        res = self.solver(x0=np.clip(x0, lbx, ubx), lbx=lbx, ubx=ubx, lbg=lbg, ubg=ubg, p=p)
        stats = self.solver.stats()
        ok = bool(stats.get("success", False)) or stats.get("return_status") == "Solved_To_Acceptable_Level"
        return float(self.energy_fun(res["x"], p)), ok


def follower_on_grid(opt: FullRouteOptimum, params, trip: FollowerTrip) -> dict[str, Any]:
    """The follower's drive in the optimum's model: speed at the nodes (interpolated over distance), the wheel force
    the dynamics need, regeneration first up to the drive's force and power limits, friction brake beyond; its
    model energy [J], grid time [s], node times [s], decision vector, and its largest acceleration / deceleration
    on the grid [m/s^2]."""
    ocp, n = opt.ocp, opt.ocp.n
    nodes = opt.preview.s
    v = np.interp(nodes, trip.s, trip.v)
    e = 0.5 * v ** 2
    f = ocp._formulate()
    p = ocp._params(0.0, opt.preview, params, 0.0)
    x0 = np.concatenate([e, np.zeros(3 * n)])
    net = np.asarray(ca.Function("g", [f["x"], f["p"]], [f["g"]])(x0, p)).ravel()[:n]  # kN, + = traction
    vm = 0.5 * (v[:-1] + v[1:])
    en = ocp.energy
    regen_cap = np.minimum(np.asarray(en.max_regen_force(opt.preview.ratio), float) / 1000.0 + 0.0 * vm,
                           (en.max_regen_power if en.regenerates else 0.0) / 1000.0 / vm)
    ft = np.maximum(net, 0.0)
    fr = np.minimum(np.maximum(-net, 0.0), regen_cap)
    fb = np.maximum(-net, 0.0) - fr
    x = np.concatenate([e, ft, fr, fb])
    energy = float(ca.Function("energy", [f["x"], f["p"]], [f["energy"] * 1000.0])(x, p))
    dt = np.diff(nodes) / vm
    acc = np.diff(e) / np.diff(nodes)
    return {"energy_J": energy, "time_s": float(dt.sum()), "node_times": np.cumsum(dt), "x": x,
            "accel_max": float(acc.max()), "decel_max": float(-acc.min())}


def later_headroom(cfg: EcoTrafficConfig, trip: FollowerTrip, params, energy, after: float,
                   settings: OptimumSettings = LIMIT_SETTINGS) -> float:
    """Headroom [Wh/km] of the trip from ``after`` [s] on (the follower's distance, speed and time then as the
    start): what is left once the first seconds after the spawn are driven as the follower drove them."""
    k = int(np.searchsorted(trip.t, after))
    start, distance = float(trip.s[k]), float(trip.s[-1])
    opt = FullRouteOptimum(ego_road(cfg, trip.seed).profile, energy, params, settings, start=start, end=distance)
    own = follower_on_grid(opt, params, trip)
    sol = opt.solve(own["time_s"], float(trip.v[k]), float(trip.v[-1]), terminal="speed")
    return (own["energy_J"] - sol.energy_J) / 3.6 / (distance - start) if sol.success else math.nan


def episode_limit(cfg: EcoTrafficConfig, trip: FollowerTrip, settings: OptimumSettings = LIMIT_SETTINGS,
                  min_gap: float = MIN_GAP, gap_ocps: dict[int, GapLimitedOcp] | None = None,
                  after: float = 0.0) -> dict[str, Any]:
    """The follower's plant and model energy, the two limits (module docstring) and the headrooms [Wh/km]; with
    ``after`` > 0 [s] also the headroom of the trip from then on (later_headroom)."""
    road = ego_road(cfg, trip.seed)
    params = oracle_parameters(road.simulator.true_parameters(), get_preset(cfg.vehicle))
    energy = energy_model_from_spec(cfg.vehicle)
    distance = float(trip.s[-1])
    opt = FullRouteOptimum(road.profile, energy, params, settings, start=0.0, end=distance)
    own = follower_on_grid(opt, params, trip)
    v0, v_end = float(trip.v[0]), float(trip.v[-1])
    free = opt.solve(own["time_s"], v0, v_end, terminal="speed")
    t_lb = earliest_times(trip, opt.preview.s[1:], min_gap)
    clipped = int((t_lb > own["node_times"]).sum())
    t_lb = np.minimum(t_lb, own["node_times"])
    gap_ocps = {} if gap_ocps is None else gap_ocps
    if opt.n not in gap_ocps:
        gap_ocps[opt.n] = GapLimitedOcp(opt)
    behind, ok = gap_ocps[opt.n].solve(opt, params, v0, v_end, own["time_s"], t_lb, own["x"])
    per_km = 1e3 / 3600.0 / distance  # J -> Wh/km of this trip
    return {"seed": trip.seed, "crashed": trip.crashed, "distance_m": distance, "time_s": float(trip.t[-1]),
            "grid_time_s": own["time_s"], "mean_speed_kmh": distance / float(trip.t[-1]) * 3.6,
            "start_speed": v0, "end_speed": v_end,
            "follower_plant_Wh_per_km": trip.energy_J * per_km, "follower_model_Wh_per_km": own["energy_J"] * per_km,
            "limit_free_Wh_per_km": free.energy_J * per_km if free.success else float("nan"),
            "limit_behind_Wh_per_km": behind * per_km if ok else float("nan"),
            "headroom_free_Wh_per_km": (own["energy_J"] - free.energy_J) * per_km if free.success else float("nan"),
            "headroom_behind_Wh_per_km": (own["energy_J"] - behind) * per_km if ok else float("nan"),
            "headroom_later_Wh_per_km": later_headroom(cfg, trip, params, energy, after, settings) if after > 0
            else math.nan, "later_from_s": after,
            "follower_accel_max": own["accel_max"], "follower_decel_max": own["decel_max"],
            "wall_bound_clipped_nodes": clipped, "nodes": opt.n}


def measure_limit(env_config: dict[str, Any] | None = None, episodes: int = 50, min_gap: float = MIN_GAP,
                  after: float = 0.0) -> pd.DataFrame:
    """Per held-out episode: the follower against the two limits (episode_limit)."""
    if episodes < 1:
        raise RLError(f"episodes: expected >= 1, got {episodes}")
    config = {**TRAFFIC_TRAIN_CONFIG, **(env_config or {})}
    cfg = make_config(EcoTrafficConfig, config)
    env = EcoTrafficEnv(cfg)
    policy = idm_policy(cfg)
    gap_ocps: dict[int, GapLimitedOcp] = {}
    rows = []
    for k in range(episodes):
        trip = record_follower(env, policy, TRAFFIC_HELD_OUT + k)
        rows.append(episode_limit(cfg, trip, min_gap=min_gap, gap_ocps=gap_ocps, after=after))
    return pd.DataFrame(rows)


def limit_summary(table: pd.DataFrame) -> pd.DataFrame:
    """Mean and 95 % t-interval over episodes of every energy column, and the trip-weighted energies (total energy /
    total distance, the evaluation's Wh/km)."""
    from scipy import stats

    k = len(table)
    half = stats.t.ppf(0.975, k - 1) / math.sqrt(k) if k > 1 else float("nan")
    rows = []
    for col in ("follower_plant_Wh_per_km", "follower_model_Wh_per_km", "limit_free_Wh_per_km",
                "limit_behind_Wh_per_km", "headroom_free_Wh_per_km", "headroom_behind_Wh_per_km",
                "headroom_later_Wh_per_km"):
        x = table[col].to_numpy(float)
        ok = np.isfinite(x)
        if not ok.any():
            continue
        weighted = float(np.sum(x[ok] * table.distance_m[ok]) / np.sum(table.distance_m[ok])) if ok.any() else math.nan
        rows.append({"quantity": col, "episodes": int(ok.sum()), "mean": float(x[ok].mean()),
                     "ci95": float(half * x[ok].std(ddof=1)) if ok.sum() > 1 else math.nan,
                     "distance_weighted": weighted, "min": float(x[ok].min()), "max": float(x[ok].max())})
    d = (table.follower_plant_Wh_per_km - table.follower_model_Wh_per_km).to_numpy(float)
    rows.append({"quantity": "plant - model (follower)", "episodes": k, "mean": float(d.mean()),
                 "ci95": float(half * d.std(ddof=1)) if k > 1 else math.nan, "distance_weighted": math.nan,
                 "min": float(d.min()), "max": float(d.max())})
    return pd.DataFrame(rows)


def main(argv: list[str] | None = None) -> None:
    """Print the per-episode limits' summary (``scripts/traffic_limit.py``)."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--episodes", type=int, default=50, help="held-out episodes")
    ap.add_argument("--min-gap", type=float, default=MIN_GAP, help="bumper-to-bumper gap kept behind the traffic [m]")
    ap.add_argument("--after", type=float, default=0.0,
                    help="> 0: also the headroom of the trip from this time [s] on (the spawn's transient left out)")
    ap.add_argument("--config", default=None, help="EcoTraffic-v0 config as JSON text over the evaluation's "
                                                  "(safety layer on, spawn outside the envelope), e.g. a scenario "
                                                  "variant '{\"duration\": 100}'")
    ap.add_argument("--csv", default=None, help="write the per-episode table here")
    ap.add_argument("--quick", action="store_true", help="tiny run for CI")
    a = ap.parse_args(argv)
    config = json_object_option(ap, a.config)
    if a.quick:
        a.episodes = 2
        config = {"spawn": "stopping-gap", **config, "duration": 5.0, "vehicles_count": 10}  # the newest spawn too
    if a.episodes < 2:
        ap.error(f"--episodes: expected >= 2 (an interval needs two), got {a.episodes}")
    if not (math.isfinite(a.min_gap) and a.min_gap >= 0):
        ap.error(f"--min-gap: expected a gap >= 0 m, got {a.min_gap}")
    c0 = time.process_time()
    duration = make_config(EcoTrafficConfig, {**TRAFFIC_TRAIN_CONFIG, **config}).duration
    if not (math.isfinite(a.after) and 0 <= a.after < duration):
        ap.error(f"--after: expected a time in [0, {duration:g}) s (the episode's duration), got {a.after}")
    table = measure_limit(config, a.episodes, a.min_gap, a.after)
    if a.csv:
        table.to_csv(a.csv, index=False)
    print(markdown_table(limit_summary(table), floatfmt=".4g"))
    print(f"{len(table)} episodes, {time.process_time() - c0:.0f} s CPU; follower grid time - trip time: "
          f"{(table.grid_time_s - table.time_s).abs().max():.3f} s at most; bound lowered on "
          f"{int(table.wall_bound_clipped_nodes.sum())} of {int(table.nodes.sum())} nodes; follower's largest "
          f"acceleration {table.follower_accel_max.max():.2f}, deceleration {table.follower_decel_max.max():.2f} "
          f"m/s^2")
