"""Are the simulator core's trajectories bitwise those of another commit? For speed work that must not change a
single bit: every preset on a motorway, a city and a hilly road, without and with all effects, built-in driver,
the whole truth log, the final step result, energy ledger and true parameters; plus the native vector env (random
actions, observations, rewards) and EcoTraffic-v0 in four configurations (observations, rewards, flags, info,
vehicle states).

    python scripts/check_core_identity.py --ref 8efaaad          # the working tree against commit 8efaaad
    python scripts/check_core_identity.py --quick                 # CI smoke run: HEAD, one short simulator run

``--ref`` is exported with ``git archive`` into a temporary package tree (:mod:`.refcompare`); each side runs this
file in its own process and dumps its arrays, which are then compared. Exit status 1 when any array differs. This
file runs against an old package tree too: it imports from roadload only what every commit has.
"""

from __future__ import annotations

import tempfile
from typing import Any
from pathlib import Path

import numpy as np

PRESETS = ("gt_rwd", "gt_awd", "bmw_i3", "truck_40t")
ROADS = ("motorway", "city", "hilly")


def dump(out: Path, quick: bool) -> None:
    """Run every configuration in this process (whichever roadload PYTHONPATH selects) and save the arrays. Only the
    public simulator API is used (Simulator.run, truth_log, state, energy_ledger, true_parameters), so that the same
    function runs on older commits."""
    import warnings
    from dataclasses import astuple

    from roadload.envs import LateralValidityWarning, Simulator
    from roadload.gym.vector import EcoDriveVectorEnv
    from roadload.road_profiles import load_profile

    warnings.simplefilter("ignore", LateralValidityWarning)  # some presets overshoot curves of the hilly road
    arrays: dict[str, np.ndarray] = {}
    presets, roads, effects = (("bmw_i3",), ("city",), (None,)) if quick else (PRESETS, ROADS, (None, "all"))
    n = 2000 if quick else 30_000  # substeps (10 ms each)
    for vehicle in presets:
        for road in roads:
            for eff in effects:
                sim = Simulator(vehicle, load_profile(road, seed=3, length=20_000.0), effects=eff, seed=2,
                                log_capacity=n + 1)
                sim.run(duration=n * 0.01)
                key = f"{vehicle}/{road}/{eff or 'none'}"
                arrays[f"{key}/log"] = sim.truth_log().copy()
                arrays[f"{key}/state"] = np.array(astuple(sim.state)[:17], dtype=float)  # the fields every commit has
                arrays[f"{key}/energy"] = np.array(list(sim.energy_ledger().values()))
                arrays[f"{key}/truth"] = np.array(list(sim.true_parameters().values()), dtype=float)
    if not quick:  # the quick run (CI) leaves out the vector env: its kernel's cold compile on the exported side
        envs, steps = 64, 1500  # doubled the run's CPU time (30 s of 60 s)
        env = EcoDriveVectorEnv(envs, threads=1)
        obs, _ = env.reset(seed=0)
        actions = np.random.default_rng(0).uniform(-1, 1, (steps, envs, 1)).astype(np.float32)
        trace_obs, trace_reward = [obs], []
        for k in range(steps):
            obs, reward, _, _, _ = env.step(actions[k])
            trace_obs.append(obs)
            trace_reward.append(reward)
        arrays["vector_env/observations"] = np.asarray(trace_obs)
        arrays["vector_env/rewards"] = np.asarray(trace_reward)
        arrays.update(traffic_arrays())
    np.savez(out, **arrays)  # type: ignore[arg-type]  # numpy's stubs read any keyword as allow_pickle


TRAFFIC_CASES: dict[str, dict[str, Any]] = {
    "default": {},
    "lane_changes_shield": {"lane_changes": "box", "shield": {"enabled": True}},
    "curved_dense_see_behind": {"curvature": True, "vehicles_density": 1.5, "see_behind": True},
    "highway_spawn_4_lanes": {"spawn": "highway-env", "vehicles_count": 10, "lanes_count": 4, "curvature": False},
}
"""EcoTraffic-v0 configurations of the identity check: the traffic model's stages (lane changes, the safety layer,
curvature, density, the Kinematics block's see-behind, the spawn rules) and the ego's powertrain on straight and
curved roads."""


def traffic_arrays(envs: int = 32, steps: int = 400) -> dict[str, np.ndarray]:
    """EcoTraffic-v0 (native vector env, random actions, autoresets) per TRAFFIC_CASES entry, threads 1 and 2 (the
    chunks of the parallel step): observations, rewards, flags, every info row and the vehicle states."""
    from roadload.gym.traffic import INFO_KEYS, EcoTrafficVectorEnv

    arrays: dict[str, np.ndarray] = {}
    for name, cfg in TRAFFIC_CASES.items():
        for threads in (1, 2):
            env = EcoTrafficVectorEnv(envs, config=cfg, threads=threads)
            obs, _ = env.reset(seed=7)
            shape = env.single_action_space.shape
            assert shape is not None  # a Box action space
            d = shape[0]
            actions = np.random.default_rng(7).uniform(-1, 1, (steps, envs, d)).astype(np.float32)
            trace: dict[str, list] = {"obs": [obs], "reward": [], "flags": [], "info": [], "vehicles": []}
            for k in range(steps):
                obs, reward, term, trunc, info = env.step(actions[k])
                trace["obs"].append(obs)
                trace["reward"].append(reward)
                trace["flags"].append(np.stack([term, trunc]))
                trace["info"].append(np.stack([np.asarray(info[key], dtype=float) for key in INFO_KEYS]))
                trace["vehicles"].append(env.vehicles)
            for key, rows in trace.items():
                arrays[f"traffic/{name}/threads{threads}/{key}"] = np.asarray(rows)
    return arrays


def compare(ref: str, quick: bool, repo: Path | None = None) -> int:
    """Dump the arrays of commit ``ref`` (of the git repository ``repo``, default: the source tree of this file)
    and of the working tree, each in its own process, and count the arrays that differ; returns the exit status."""
    # imported here, not at the top: this file also runs against old package trees that lack the module
    from roadload.experiments.benchmarks.refcompare import REPO, dump_pair

    repo = repo or REPO
    with tempfile.TemporaryDirectory(prefix="roadload-identity-") as tmp:
        old, new = dump_pair(Path(__file__).resolve(), ref, quick, Path(tmp), repo)
        a, b = np.load(old), np.load(new)
        differ = []
        for key in a.files:
            if key not in b.files or a[key].shape != b[key].shape or not np.array_equal(a[key], b[key],
                                                                                       equal_nan=True):
                differ.append(key)
        values = sum(a[k].size for k in a.files)
    print(f"{ref} vs working tree ({repo}): {len(a.files)} arrays ({values:,} values) compared, "
          f"{len(differ)} differ")
    for key in differ:
        print(f"  differs: {key}")
    return 1 if differ else 0


def main(argv: list[str] | None = None, repo: Path | None = None) -> int:
    """The check's command line (``scripts/check_core_identity.py``); returns the exit status."""
    # imported here, not at the top: this file also runs against old package trees that lack the module
    from roadload.experiments.benchmarks.refcompare import identity_command

    return identity_command(__doc__ or "", "one short simulator run, no vector env (CI smoke run)", compare, argv, repo)


if __name__ == "__main__":
    raise SystemExit(main())
