"""Environment speed: steps per second of the single env, process/dummy vectorisation and the native vector env."""

from __future__ import annotations

import os
import time
from typing import Any, Callable

import numpy as np
import pandas as pd

from .common import make_vec_env
from roadload.gym.vector import EcoDriveVectorEnv


# --------------------------------------------------------------------------------------------- speed benchmark
def _steps_per_second(step: Callable[[], None], seconds: float) -> tuple[float, int]:
    n = 0
    t0 = time.perf_counter()
    while True:
        step()
        n += 1
        if n % 64 == 0 and time.perf_counter() - t0 >= seconds:
            break
    return n / (time.perf_counter() - t0), n


def bench_single(env_id: str, seconds: float = 5.0, seed: int = 0, **kwargs) -> dict[str, Any]:
    """Single-process steps/s of ``env_id`` under uniformly random actions (resets included)."""
    import gymnasium as gym

    env = gym.make(env_id, **kwargs)
    env.reset(seed=seed)
    env.action_space.seed(seed)
    for _ in range(50):  # warm-up (numba cache load, first allocations)
        _, _, te, tr, _ = env.step(env.action_space.sample())
        if te or tr:
            env.reset()

    episodes = [0]

    def step() -> None:
        _, _, te, tr, _ = env.step(env.action_space.sample())
        if te or tr:
            env.reset()
            episodes[0] += 1

    rate, n = _steps_per_second(step, seconds)
    env.close()
    return {"env": env_id, "mode": "single process", "steps_per_s": rate, "steps": n, "episodes": episodes[0]}


def bench_vectorised(n_envs: int = 2, seconds: float = 5.0, vec: str = "subproc",
                     env_config: dict[str, Any] | None = None) -> dict[str, Any]:
    """Steps/s (summed over envs) of EcoDrive-v0 in an SB3 vectorised env with random actions."""
    venv = make_vec_env(n_envs, 0, env_config, vec=vec)
    try:
        venv.reset()
        rng = np.random.default_rng(0)
        acts = rng.uniform(-1, 1, (4096, n_envs, 1)).astype(np.float32)
        k = [0]

        def step() -> None:
            venv.step(acts[k[0] % 4096])
            k[0] += 1

        for _ in range(50):
            step()
        rate, n = _steps_per_second(step, seconds)
    finally:
        venv.close()
    return {"env": "roadload/EcoDrive-v0", "mode": f"{vec} x{n_envs}", "steps_per_s": rate * n_envs,
            "steps": n * n_envs, "episodes": None}


def call_rates(step: Callable[[], None], seconds: float) -> tuple[float, float, int]:
    """(calls per wall second, calls per CPU second of this process, calls): CPU seconds make runs on a machine
    shared with other jobs comparable (wall rates there measure the share the scheduler gave us)."""
    n = 0
    t0, c0 = time.perf_counter(), time.process_time()
    while True:
        step()
        n += 1
        if n % 8 == 0 and time.perf_counter() - t0 >= seconds:
            break
    return n / (time.perf_counter() - t0), n / max(time.process_time() - c0, 1e-9), n


def random_action_stepper(env: Any) -> Callable[[], None]:
    """One step of a single env under random actions (reset with seed 0 first, actions seeded 0), resetting at
    the end of an episode."""
    env.reset(seed=0)
    env.action_space.seed(0)

    def step() -> None:
        _, _, te, tr, _ = env.step(env.action_space.sample())
        if te or tr:
            env.reset()
    return step


def bench_native(n_envs: int = 256, seconds: float = 5.0, threads: int = 1, bare: bool = False,
                 env_config: dict[str, Any] | None = None) -> dict[str, Any]:
    """Env steps/s (summed over sub-envs, wall and per CPU second) of the native vector env under random actions
    in [-1, 1] (autoresets included), or with ``bare`` only its batched physics (no reward / observation / info /
    autoreset): the reference the env step is compared with."""

    venv = EcoDriveVectorEnv(n_envs, config=dict(env_config or {}), threads=threads)
    venv.reset(seed=0)
    acts = np.random.default_rng(0).uniform(-1, 1, (256, n_envs, 1)).astype(np.float32)
    k = [0]
    fn = venv.bare_physics_step if bare else venv.step

    def step() -> None:
        fn(acts[k[0] % 256])
        k[0] += 1

    for _ in range(3):
        step()
    wall, cpu, n = call_rates(step, seconds)
    mode = f"{'bare batched physics' if bare else 'native vector env'} x{n_envs}, {threads} thread(s)"
    return {"env": "roadload/EcoDrive-v0", "mode": mode, "steps_per_s": wall * n_envs,
            "steps_per_cpu_s": cpu * n_envs, "steps": n * n_envs}


def load_average() -> float:
    """The 1-minute load average (NaN where the OS has none): on a shared 2-core machine a load above ~1 means
    another process holds a core, which stalls every step of a 2-thread env at its barrier."""
    return os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")


def run_native_benchmark(seconds: float = 5.0, n_envs: int = 256, n_dummy: int = 16,
                         progress: Callable[[str], None] | None = None,
                         threads: tuple[int, ...] = (1, 2)) -> pd.DataFrame:
    """The batched-env table (same run): single env, SB3 DummyVecEnv x n_dummy, then for each thread count in
    ``threads`` the native vector env x n_envs and its bare batched physics with the same thread count (the
    like-for-like reference), as wall and per-CPU-second rates; ``load_1min`` = the load average as the row
    started."""
    if not threads or any(isinstance(t, bool) or int(t) != t or t < 1 for t in threads):
        raise ValueError(f"threads: expected thread counts >= 1, e.g. (1, 2), got {threads!r}")
    rows = []

    def add(row: dict[str, Any], load: float) -> None:
        rows.append({**row, "load_1min": load})
        if progress:
            progress(row["mode"])

    import gymnasium as gym

    env = gym.make("roadload/EcoDrive-v0")
    load = load_average()
    wall, cpu, n = call_rates(random_action_stepper(env), seconds)
    add({"env": "roadload/EcoDrive-v0", "mode": "single process", "threads": 1, "steps_per_s": wall,
         "steps_per_cpu_s": cpu, "steps": n}, load)
    venv = make_vec_env(n_dummy, 0, None, vec="dummy")
    try:
        venv.reset()
        acts = np.random.default_rng(0).uniform(-1, 1, (256, n_dummy, 1)).astype(np.float32)
        k = [0]

        def dummy() -> None:
            venv.step(acts[k[0] % 256])
            k[0] += 1

        load = load_average()
        wall, cpu, n = call_rates(dummy, seconds)
    finally:
        venv.close()
    add({"env": "roadload/EcoDrive-v0", "mode": f"dummy x{n_dummy}", "threads": 1, "steps_per_s": wall * n_dummy,
         "steps_per_cpu_s": cpu * n_dummy, "steps": n * n_dummy}, load)
    for t in threads:
        for bare in (False, True):
            load = load_average()
            add({**bench_native(n_envs, seconds, int(t), bare=bare), "threads": int(t)}, load)
    return pd.DataFrame(rows)


def native_ratios(table: pd.DataFrame) -> pd.DataFrame:
    """Per thread count of a :func:`run_native_benchmark` table: the native env's wall and CPU rates, and its
    ratios to the bare batched physics with the same thread count and to the DummyVecEnv (per CPU second)."""
    dummy = table[table["mode"].str.startswith("dummy")].iloc[0]
    out = []
    batched = table[table["mode"].str.startswith(("native", "bare"))]
    for t, grp in batched.groupby("threads"):
        env = grp[grp["mode"].str.startswith("native")].iloc[0]
        bare = grp[grp["mode"].str.startswith("bare")].iloc[0]
        out.append({"threads": int(t), "native_steps_per_s": env.steps_per_s,
                    "native_steps_per_cpu_s": env.steps_per_cpu_s,
                    "native_over_bare_wall": env.steps_per_s / bare.steps_per_s,
                    "native_over_bare_cpu": env.steps_per_cpu_s / bare.steps_per_cpu_s,
                    "native_over_dummy_cpu": env.steps_per_cpu_s / dummy.steps_per_cpu_s,
                    "load_1min": env.load_1min})
    return pd.DataFrame(out)


def run_benchmark(seconds: float = 5.0, n_envs: int = 2, include_highway: bool = True,
                  progress: Callable[[str], None] | None = None) -> pd.DataFrame:
    """The speed table: EcoDrive-v0 (state and can observations) single process, vectorised (dummy and subproc
    x n_envs), EcoHighway-v0 and highway-env's highway-fast-v0 measured in the same run."""
    rows = []

    def note(msg):
        if progress:
            progress(msg)

    rows.append(bench_single("roadload/EcoDrive-v0", seconds))
    note("EcoDrive-v0 single")
    rows.append({**bench_single("roadload/EcoDrive-v0", seconds, observation="can"),
                 "env": "roadload/EcoDrive-v0 (observation=can)"})
    note("EcoDrive-v0 can")
    rows.append(bench_vectorised(n_envs, seconds, "dummy"))
    note("EcoDrive-v0 dummy")
    rows.append(bench_vectorised(n_envs, seconds, "subproc"))
    note("EcoDrive-v0 subproc")
    if include_highway:
        import highway_env
        import gymnasium as gym

        gym.register_envs(highway_env)
        rows.append(bench_single("roadload/EcoHighway-v0", seconds))
        note("EcoHighway-v0")
        rows.append(bench_single("highway-fast-v0", seconds))
        note("highway-fast-v0")
    table = pd.DataFrame(rows)
    step_time = {"roadload/EcoDrive-v0": 0.1, "roadload/EcoDrive-v0 (observation=can)": 0.1,
                 "roadload/EcoHighway-v0": 0.5, "highway-fast-v0": 1.0}
    table["simulated_s_per_step"] = table["env"].map(step_time)
    table["simulated_s_per_wall_s"] = table["steps_per_s"] * table["simulated_s_per_step"]
    return table


def speed_ratio(table: pd.DataFrame) -> float:
    """EcoDrive-v0 single-process steps/s divided by highway-fast-v0's (same run)."""
    eco = table[(table.env == "roadload/EcoDrive-v0") & (table["mode"] == "single process")].steps_per_s
    hw = table[table.env == "highway-fast-v0"].steps_per_s
    if eco.empty or hw.empty:
        return float("nan")
    return float(eco.iloc[0] / hw.iloc[0])
