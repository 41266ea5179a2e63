"""Where one batch step of the native vector env (roadload/EcoDrive-v0, N sub-envs, random actions in [-1, 1],
autoresets included) spends its time: the compiled step, the episode setups of the autoresets (road generation,
simulator, route table), and the rest of step() in Python (action check, info dict, copies), in CPU milliseconds
per batch step (process CPU clock: robust to other jobs on a shared machine, unlike wall time).

    python scripts/profile_vector_env.py [--threads 1] [--steps 3000] [--native 256]
    python scripts/profile_vector_env.py --quick                                         # CI smoke run
    PYTHONPATH=<exported old tree> python scripts/profile_vector_env.py                 # the same for an old commit

With k threads the compiled step runs in parallel and the rest is serial, so on k idle cores a batch step takes
about compiled / k + setups + rest (wall, perfect scaling of the compiled step assumed: the bare batched physics
scaled 1.95x on 2 idle cores); from a 1-thread run the script prints that estimate for 2 threads, an estimate
and not a measurement (bench_gym.py measures).
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from roadload.gym.vector import EcoDriveVectorEnv


def profile(n_envs: int, steps: int, threads: int) -> dict[str, float]:
    """CPU ms per batch step of the compiled step, the autoreset setups and the rest; wall ms; resets."""
    env = EcoDriveVectorEnv(n_envs, threads=threads)
    env.reset(seed=0)
    actions = np.random.default_rng(0).uniform(-1, 1, (256, n_envs, 1)).astype(np.float32)
    for k in range(3):
        env.step(actions[k])
    spent = {"compiled": 0.0, "setups": 0.0}
    count = [0]

    def timed(name, fn):
        def call(*a, **kw):
            c0 = time.process_time()
            out = fn(*a, **kw)
            spent[name] += time.process_time() - c0
            count[0] += name == "setups"
            return out
        return call

    # the profile times the env's own compiled step and episode setups by wrapping them on this instance
    if hasattr(env, "batch"):  # the compiled step of the shared EcoDrive batch
        env.batch.step = timed("compiled", env.batch.step)  # type: ignore[method-assign]
    else:  # older commits
        env._step_compiled = timed("compiled", env._step_compiled)  # type: ignore[attr-defined]
    env._reset_one = timed("setups", env._reset_one)  # type: ignore[method-assign]
    c0, w0 = time.process_time(), time.perf_counter()
    for k in range(steps):
        env.step(actions[k % 256])
    cpu, wall = time.process_time() - c0, time.perf_counter() - w0
    ms = 1e3 / steps
    return {"compiled": spent["compiled"] * ms, "setups": spent["setups"] * ms,
            "rest": (cpu - spent["compiled"] - spent["setups"]) * ms, "cpu": cpu * ms, "wall": wall * ms,
            "resets": count[0], "setup_ms": spent["setups"] / max(count[0], 1) * 1e3}


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--threads", type=int, default=1, help="numba threads of the env")
    ap.add_argument("--steps", type=int, default=3000, help="batch steps measured")
    ap.add_argument("--native", type=int, default=256, help="sub-envs")
    ap.add_argument("--quick", action="store_true", help="tiny run for CI")
    args = ap.parse_args(argv)
    if args.quick:
        args.steps, args.native = 200, 32
    r = profile(args.native, args.steps, args.threads)
    n = args.native
    print(f"N = {n}, {args.threads} thread(s), {args.steps} batch steps, {r['resets']} autoresets "
          f"({r['setup_ms']:.2f} ms CPU each)")
    print(f"CPU ms per batch step: compiled step {r['compiled']:.3f} | episode setups {r['setups']:.3f} | "
          f"rest of step() {r['rest']:.3f} | total {r['cpu']:.3f} ({n / r['cpu'] * 1e3:,.0f} env steps per CPU s)")
    print(f"wall ms per batch step {r['wall']:.3f} ({n / r['wall'] * 1e3:,.0f} env steps/s)")
    if args.threads == 1:
        est = r["compiled"] / 2 + r["setups"] + r["rest"]
        print(f"estimate for 2 threads on 2 idle cores (compiled / 2 + serial): {est:.3f} ms per batch step "
              f"({n / est * 1e3:,.0f} env steps/s)")
