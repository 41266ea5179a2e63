"""Fidelity of ``roadload/EcoTraffic-v0`` (native backend) against ``roadload/EcoHighway-v0`` (highway-env, the
reference) on the same scenario, both egos driven by the same IDM follower (roadload.experiments.rl.highway).

Scenario: EcoTraffic-v0's configuration with a straight road (``curvature=False``, as highway-env's) and its
equivalent EcoHighway-v0 configuration (roadload.gym.traffic_reference.highway_config: lanes, density, vehicle
count, IDM/MOBIL parameters, frequencies, duration). Episode k is reset with seed ``seed0 + k`` on both backends
(each draws its traffic from its own generator: the same distribution, different draws) and with the same road
seed (the same grade under both egos).

Measured from the vehicle states after every env step, with one function for both backends
(:func:`traffic_samples`):

- speed of every traffic vehicle [m/s];
- time headway of every traffic vehicle with a leader on its lane: bumper gap / speed [s] (leader = the nearest
  vehicle ahead within 3 m of the lane's centre line, the ego included, as highway-env's neighbour search);
- lane changes of the traffic: changes of a vehicle's lane between steps, per vehicle and minute;
- per episode: the ego crashed; its source energy, distance and mean speed (energy per km = total energy / total
  distance over the episodes).

The table gives each backend's figure, the relative difference native / reference - 1 with a 95 % bootstrap
interval over episodes, the two-sample Kolmogorov-Smirnov distance of the speed and headway distributions, and the
target of each row. ``--paired`` starts highway-env from each native episode's start state instead of its own
draw: the same traffic and road in both, so what differs is the models. Command line: :func:`main`
(``scripts/traffic_fidelity.py``).

    python scripts/traffic_fidelity.py --episodes 100 --out docs/results/traffic     # ~25 min (highway-env side)
    python scripts/traffic_fidelity.py --quick                                       # CI smoke run (2 episodes)
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from dataclasses import dataclass, field
from typing import Any, Callable

from pathlib import Path

import numpy as np
import pandas as pd

from roadload.gym.config import EcoTrafficConfig, make_config
from roadload.gym.highway import EcoHighwayEnv
from roadload.gym.traffic import EcoTrafficEnv
from roadload.gym.traffic_model import (LANE_MARGIN, LANE_WIDTH, LENGTH, V_DELTA, V_LANE, V_SPEED, V_TIMER, V_X,
                                        V_Y)
from roadload.gym.traffic_reference import highway_config
from roadload.tables import markdown_table, write_csv

from .common import json_object_option

from .highway import idm_policy

FIDELITY_TARGETS = {"headway_median_s": 0.10, "speed_median_mps": 0.10, "lane_changes_per_vehicle_min": 0.25,
                    "ego_energy_Wh_per_km": 0.03}
"""Relative tolerance of each compared figure (|native / reference - 1|)."""
BACKENDS = ("native", "highway-env")


@dataclass
class EpisodeSamples:
    """What one episode gave (module docstring)."""

    speeds: list[np.ndarray] = field(default_factory=list)
    headways: list[np.ndarray] = field(default_factory=list)
    lane_changes: int = 0
    vehicle_minutes: float = 0.0
    crashed: bool = False
    energy_J: float = 0.0
    distance_m: float = 0.0
    duration_s: float = 0.0


def vehicle_arrays(env: Any) -> np.ndarray:
    """(vehicles, 4) x [m], y [m], speed [m/s], lane of every vehicle (row 0 the ego) of either backend."""
    if isinstance(env, EcoTrafficEnv):
        v = env.vehicles
        return v[:, [V_X, V_Y, V_SPEED, V_LANE]]
    return np.array([[veh.position[0], veh.position[1], veh.speed, veh.lane_index[2]] for veh in env.road.vehicles])


def time_headways(state: np.ndarray, lanes: int) -> np.ndarray:
    """Bumper gap / speed [s] of every traffic vehicle (rows 1..) with a leader on its lane and speed > 0.1 m/s."""
    x, y, v, lane = state[:, 0], state[:, 1], state[:, 2], state[:, 3].astype(int)
    on = np.abs(y[None, :] - np.arange(lanes)[:, None] * LANE_WIDTH) <= LANE_WIDTH / 2 + LANE_MARGIN  # (lanes, n)
    out = []
    for j in range(1, len(x)):
        ahead = on[lane[j]] & (x >= x[j])
        ahead[j] = False
        if not ahead.any() or v[j] <= 0.1:
            continue
        gap = x[ahead].min() - x[j] - LENGTH
        out.append(gap / v[j])
    return np.asarray(out)


def place_vehicles(env: EcoHighwayEnv, start: np.ndarray) -> np.ndarray:
    """Put EcoHighway-v0's freshly reset vehicles into the native episode's start state ``start`` (rows of
    roadload.gym.traffic_model.V_*: position, lane, speed, desired speed, IDM exponent, decision timer; the ego's
    speed is already its initial speed); returns the observation of that state."""
    vehicles = env.road.vehicles
    if len(vehicles) != start.shape[0]:
        raise ValueError(f"start: {start.shape[0]} vehicles, EcoHighway-v0 has {len(vehicles)}")
    for v, row in zip(vehicles, start):
        lane = ("0", "1", int(row[V_LANE]))
        v.position = np.array([row[V_X], row[V_Y]])
        v.heading = 0.0
        v.target_lane_index = lane
        if v is not env.vehicle:
            v.speed = v.target_speed = float(row[V_SPEED])
            v.DELTA = float(row[V_DELTA])
            v.timer = float(row[V_TIMER])
        v.on_state_update()
    return env.observation_type.observe()


def run_episode(env: Any, policy: Callable[[np.ndarray], np.ndarray], seed: int, road_seed: int,
                lanes: int, step_time: float, start: np.ndarray | None = None) -> EpisodeSamples:
    """One episode of either backend under ``policy`` with the episode seed and road seed given (``start``: the
    vehicles' start state to place on highway-env instead of its own draw)."""
    obs, info = env.reset(seed=int(seed), options={"road_seed": int(road_seed)})
    if start is not None:
        obs = place_vehicles(env, start)
    out = EpisodeSamples()
    state = vehicle_arrays(env)
    e0 = info["source_energy_total"]
    done = False
    while not done:
        obs, _, terminated, truncated, info = env.step(policy(obs))
        done = terminated or truncated
        new = vehicle_arrays(env)
        out.speeds.append(new[1:, 2].copy())
        out.headways.append(time_headways(new, lanes))
        out.lane_changes += int(np.count_nonzero(new[1:, 3] != state[1:, 3]))
        out.vehicle_minutes += (len(new) - 1) * step_time / 60.0
        state = new
    out.crashed = bool(info["crashed"])
    out.energy_J = float(info["source_energy_total"] - e0)
    out.distance_m = float(info["s"])
    out.duration_s = float(info["t"])
    return out


def make_backend(backend: str, cfg: EcoTrafficConfig) -> Any:
    if backend == "native":
        return EcoTrafficEnv(cfg)
    if backend == "highway-env":
        return EcoHighwayEnv(highway_config(cfg))
    raise ValueError(f"backend: expected one of {BACKENDS}, got {backend!r}")


def native_starts(cfg: EcoTrafficConfig, episodes: int, seed0: int = 0) -> list[np.ndarray]:
    """The vehicles' start states of the native episodes seed0 .. seed0 + episodes - 1 (road seeds as
    :func:`run_backend` draws them)."""
    env = EcoTrafficEnv(cfg)
    out = []
    for k, road_seed in enumerate(_road_seeds(cfg, episodes)):
        env.reset(seed=seed0 + k, options={"road_seed": int(road_seed)})
        out.append(env.vehicles)
    return out


def _road_seeds(cfg: EcoTrafficConfig, episodes: int) -> np.ndarray:
    return np.random.default_rng(12345).integers(*cfg.road_seed_range, size=episodes)


def run_backend(backend: str, cfg: EcoTrafficConfig, episodes: int, seed0: int = 0,
                progress: Callable[[str], None] | None = None,
                starts: list[np.ndarray] | None = None) -> tuple[list[EpisodeSamples], float]:
    """``episodes`` IDM-driven episodes of one backend (``starts``: highway-env placed in these start states);
    (samples, wall seconds)."""
    env = make_backend(backend, cfg)
    # the same follower on each backend's observation layout (it reads speed, front gap and closing speed)
    policy = idm_policy(cfg if backend == "native" else highway_config(cfg))
    road_seeds = _road_seeds(cfg, episodes)
    t0 = time.perf_counter()
    out = []
    for k in range(episodes):
        out.append(run_episode(env, policy, seed0 + k, int(road_seeds[k]), cfg.lanes_count,
                               1.0 / cfg.policy_frequency, None if starts is None else starts[k]))
        if progress:
            progress(f"{backend} episode {k + 1}/{episodes}")
    env.close()
    return out, time.perf_counter() - t0


# --------------------------------------------------------------------------------------------- statistics
def episode_metrics(samples: list[EpisodeSamples]) -> dict[str, np.ndarray]:
    """Per-episode sums the figures are ratios of (for the bootstrap over episodes)."""
    return {"lane_changes": np.array([s.lane_changes for s in samples], float),
            "vehicle_minutes": np.array([s.vehicle_minutes for s in samples]),
            "energy": np.array([s.energy_J for s in samples]),
            "distance": np.array([s.distance_m for s in samples]),
            "duration": np.array([s.duration_s for s in samples]),
            "crashed": np.array([s.crashed for s in samples], float)}


class _Pooled:
    """One pooled sample (all episodes' speeds or headways), sorted once with each value's episode, so that the
    median of a bootstrap resample (episode k drawn c_k times) is a weighted median: O(n), no concatenation."""

    def __init__(self, samples: list[EpisodeSamples], name: str) -> None:
        parts = [np.concatenate(getattr(s, name)) if getattr(s, name) else np.zeros(0) for s in samples]
        values = np.concatenate(parts) if parts else np.zeros(0)
        episode = np.repeat(np.arange(len(parts)), [p.size for p in parts])
        order = np.argsort(values, kind="stable")
        self.values, self.episode = values[order], episode[order]

    def median(self, counts: np.ndarray) -> float:
        """The median of the pool with episode k counted counts[k] times (np.median's when all counts are 1)."""
        if self.values.size == 0:
            return float("nan")
        if np.all(counts == 1):
            return float(np.median(self.values))
        weight = np.cumsum(counts[self.episode])
        total = weight[-1]
        if total == 0:
            return float("nan")
        lo = int(np.searchsorted(weight, (total + 1) // 2))  # the lower and upper middle of the weighted sample
        hi = int(np.searchsorted(weight, total // 2 + 1))
        return float(0.5 * (self.values[lo] + self.values[hi]))


def figures(samples: list[EpisodeSamples], idx: np.ndarray | None = None,
            pools: dict[str, _Pooled] | None = None) -> dict[str, float]:
    """The compared figures over the episodes ``idx`` (all by default; repeated indices count repeatedly)."""
    counts = np.ones(len(samples), dtype=np.int64) if idx is None else np.bincount(idx, minlength=len(samples))
    pools = pools or {k: _Pooled(samples, k) for k in ("speeds", "headways")}
    m = {k: (v * counts).sum() for k, v in episode_metrics(samples).items()}
    n = max(counts.sum(), 1)
    return {"headway_median_s": pools["headways"].median(counts),
            "speed_median_mps": pools["speeds"].median(counts),
            "lane_changes_per_vehicle_min": float(m["lane_changes"] / max(m["vehicle_minutes"], 1e-9)),
            "ego_energy_Wh_per_km": float(m["energy"] / 3.6 / max(m["distance"], 1e-9)),
            "ego_collision_rate": float(m["crashed"] / n),
            "ego_mean_speed_kmh": float(m["distance"] / max(m["duration"], 1e-9) * 3.6)}


def ks_distance(a: np.ndarray, b: np.ndarray) -> float:
    """Two-sample Kolmogorov-Smirnov statistic sup |F_a - F_b|."""
    a, b = np.sort(a), np.sort(b)
    grid = np.concatenate([a, b])
    return float(np.max(np.abs(np.searchsorted(a, grid, side="right") / a.size
                               - np.searchsorted(b, grid, side="right") / b.size)))


def fidelity_table(native: list[EpisodeSamples], reference: list[EpisodeSamples], n_boot: int = 400,
                   seed: int = 0, paired: bool = False) -> pd.DataFrame:
    """One row per figure: native, reference, native / reference - 1, its 95 % bootstrap interval (episodes
    resampled independently on each backend, or together when ``paired``), the target, and whether the point
    estimate meets it."""
    pn = {k: _Pooled(native, k) for k in ("speeds", "headways")}
    pr = {k: _Pooled(reference, k) for k in ("speeds", "headways")}
    fn, fr = figures(native, pools=pn), figures(reference, pools=pr)
    rng = np.random.default_rng(seed)
    boots: dict[str, list[float]] = {k: [] for k in fn}
    for _ in range(n_boot):
        idx_n = rng.integers(0, len(native), len(native))
        idx_r = idx_n if paired else rng.integers(0, len(reference), len(reference))
        bn = figures(native, idx_n, pn)
        br = figures(reference, idx_r, pr)
        for k in fn:
            boots[k].append(bn[k] / br[k] - 1.0 if br[k] not in (0.0,) and np.isfinite(br[k]) else np.nan)
    rows = []
    for k in fn:
        rel = fn[k] / fr[k] - 1.0 if fr[k] != 0 else float("nan")
        lo, hi = np.nanpercentile(boots[k], [2.5, 97.5]) if np.isfinite(boots[k]).any() else (np.nan, np.nan)
        tol = FIDELITY_TARGETS.get(k)
        rows.append({"figure": k, "native": fn[k], "highway-env": fr[k], "rel_diff": rel, "ci_low": lo, "ci_high": hi,
                     "target": f"within {tol:.0%}" if tol is not None else "reported",
                     "met": (abs(rel) <= tol) if tol is not None else None})
    rows.append({"figure": "speed KS distance", "native": ks_distance(pn["speeds"].values, pr["speeds"].values),
                 "target": "reported"})
    rows.append({"figure": "headway KS distance",
                 "native": ks_distance(pn["headways"].values, pr["headways"].values), "target": "reported"})
    return pd.DataFrame(rows)


def save_samples(path: Path, native: list[EpisodeSamples], reference: list[EpisodeSamples]) -> None:
    """Both backends' samples in one .npz (numpy's open format): per backend the pooled speeds and headways with
    their episode index and the per-episode sums (episode_metrics), so the table can be recomputed."""
    arrays: dict[str, np.ndarray] = {}
    for name, samples in (("native", native), ("highway_env", reference)):
        for k in ("speeds", "headways"):
            pool = _Pooled(samples, k)
            arrays[f"{name}_{k}"] = pool.values
            arrays[f"{name}_{k}_episode"] = pool.episode
        for k, v in episode_metrics(samples).items():
            arrays[f"{name}_{k}"] = v
    np.savez_compressed(path, **arrays)  # type: ignore[arg-type]  # numpy's stub types **kwds as allow_pickle


def paired_episodes(native: list[EpisodeSamples], reference: list[EpisodeSamples]) -> pd.DataFrame:
    """Per episode of a paired run: each backend's ego energy per km [Wh/km], distance [m], crash, lane changes of
    the traffic, and the relative energy difference."""
    rows = []
    for k, (n, r) in enumerate(zip(native, reference)):
        en, er = n.energy_J / 3.6 / max(n.distance_m, 1e-9), r.energy_J / 3.6 / max(r.distance_m, 1e-9)
        rows.append({"episode": k, "native_Wh_per_km": en, "highway_env_Wh_per_km": er,
                     "native_distance_m": n.distance_m, "highway_env_distance_m": r.distance_m,
                     "native_crashed": n.crashed, "highway_env_crashed": r.crashed,
                     "native_lane_changes": n.lane_changes, "highway_env_lane_changes": r.lane_changes})
    return pd.DataFrame(rows)


def run_fidelity(episodes: int = 60, native_episodes: int | None = None, env_config: dict[str, Any] | None = None,
                 seed0: int = 0, progress: Callable[[str], None] | None = None,
                 paired: bool = False) -> dict[str, Any]:
    """Both backends on the scenario (module docstring): the table, per-backend wall times and the samples.
    ``paired``: highway-env starts every episode from the native episode's start state (same traffic, same road),
    so the differences are the models' and not the draws'."""
    cfg = make_config(EcoTrafficConfig, {"curvature": False, **(env_config or {})})
    if paired and native_episodes not in (None, episodes):
        raise ValueError("paired: both backends run the same episodes (leave native_episodes unset)")
    native, t_native = run_backend("native", cfg, native_episodes or episodes, seed0, progress)
    starts = native_starts(cfg, episodes, seed0) if paired else None
    reference, t_ref = run_backend("highway-env", cfg, episodes, seed0, progress, starts)
    return {"table": fidelity_table(native, reference, paired=paired),
            "seconds": {"native": t_native, "highway-env": t_ref},
            "episodes": {"native": len(native), "highway-env": len(reference)}, "config": cfg,
            "native": native, "reference": reference}


def main(argv: list[str] | None = None) -> None:
    """Run both backends, print the table, write it (``scripts/traffic_fidelity.py``; module docstring)."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--episodes", type=int, default=100, help="IDM episodes on highway-env")
    ap.add_argument("--native-episodes", type=int, default=None, help="IDM episodes on the native backend "
                                                                       "(default: as many)")
    ap.add_argument("--config", default=None, help="EcoTraffic-v0 config as JSON text (curvature is set False)")
    ap.add_argument("--out", type=Path, default=None, help="folder for fidelity.csv / fidelity.md / fidelity.json")
    ap.add_argument("--paired", action="store_true", help="highway-env starts from the native episodes' start "
                                                          "states (same traffic and road per episode)")
    ap.add_argument("--quick", action="store_true", help="2 short episodes per backend")
    a = ap.parse_args(argv)
    config = json_object_option(ap, a.config)
    if a.quick:
        a.episodes, a.native_episodes = 2, 2
        config = {"duration": 5.0, "vehicles_count": 10, **config}
        a.out = a.out or Path(tempfile.mkdtemp(prefix="roadload-fidelity-"))
    if a.episodes < 1:
        ap.error("--episodes must be >= 1")
    res = run_fidelity(a.episodes, None if a.paired else a.native_episodes, config,
                       progress=lambda m: print(m, flush=True) if m.endswith("0/" + str(a.episodes)) else None,
                       paired=a.paired)
    table = res["table"]
    print(markdown_table(table, floatfmt=".4g"))
    print(f"episodes: {res['episodes']}; wall seconds: {({k: round(v, 1) for k, v in res['seconds'].items()})}")
    if a.out:
        a.out.mkdir(parents=True, exist_ok=True)
        stem = "fidelity_paired" if a.paired else "fidelity"
        write_csv(a.out / f"{stem}.csv", table)
        (a.out / f"{stem}.md").write_text(markdown_table(table, floatfmt=".4g") + "\n")
        (a.out / f"{stem}.json").write_text(json.dumps(
            {"episodes": res["episodes"], "seconds": res["seconds"], "paired": a.paired,
             "config": res["config"].model_dump()}, indent=1, default=str))
        if a.paired:
            write_csv(a.out / "fidelity_paired_episodes.csv", paired_episodes(res["native"], res["reference"]))
        save_samples(a.out / f"{stem}_samples.npz", res["native"], res["reference"])
        print(f"written to {a.out}")
