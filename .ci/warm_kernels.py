"""Compile roadload's numba kernels into the cache of the installed package once, before ``pytest -n 2``.

On an empty cache each xdist worker compiles every kernel its tests reach (the simulator core, the estimator's
record loop for each parameter count, the gym envs' step kernels): two workers compile the same kernels, ~80 s
of CPU each. Warming the cache first compiles each kernel once, in groups that share no kernel, two groups at a
time (one process each, so both cores work); the tests, the scripts and the docs then load machine code.

Each group drives the public API at a tiny size with the argument types the tests use (a kernel compiles once per
type signature: the estimator loop once per parameter count 1-6, the simulator once for a single vehicle and once
for a fleet). A kernel this misses is compiled by the first test that reaches it, as before: nothing is skipped.

    python .ci/warm_kernels.py [--jobs 2]          # every group, two at a time; prints each group's wall and CPU
    python .ci/warm_kernels.py --group gym  # one group in this process
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time
from collections.abc import Callable


def simulator() -> None:
    """The simulator core for one vehicle (electric, combustion with gears, truck) and for a fleet (batch API)."""
    import numpy as np

    from roadload.envs import simulate
    from roadload.envs.batch import Fleet, advance_vehicles
    from roadload.envs.simulator import Simulator
    from roadload.road_profiles import load_profile

    road = load_profile("hilly", seed=1, length=1000.0)
    for vehicle in ("bmw_i3", "gt_rwd"):
        simulate(vehicle, road, effects="all", seed=1, duration=10.0)
    fleet = Fleet(2)  # one vehicle spec per fleet
    for i in range(2):
        fleet.load(i, Simulator("bmw_i3", road, seed=i))
    advance_vehicles(fleet.records, np.array([True, True]), 10)


def gym() -> None:
    """The gym envs' kernels: EcoDrive-v0 single and native vector, EcoTraffic-v0 single and vector."""
    import numpy as np

    from roadload.gym.ecodrive import EcoDriveEnv
    from roadload.gym.traffic import EcoTrafficEnv, EcoTrafficVectorEnv
    from roadload.gym.vector import EcoDriveVectorEnv

    for env in (EcoDriveEnv(config={"route_length": 200.0}), EcoTrafficEnv(vehicles_count=10, duration=2.0)):
        env.reset(seed=1)
        for _ in range(3):
            env.step(env.action_space.sample())
    for venv in (EcoDriveVectorEnv(2, config={"route_length": 200.0}),
                 EcoTrafficVectorEnv(2, vehicles_count=10, duration=2.0)):
        venv.reset(seed=1)
        for _ in range(3):
            venv.step(np.stack([venv.single_action_space.sample() for _ in range(2)]))


def _record_loops(counts: range, gtls_counts: range) -> None:
    """The recursive estimators' record loop for each parameter count in ``counts`` (one compilation per count),
    the RGTLS loop for each in ``gtls_counts``."""
    import numpy as np

    from roadload.estimators import RecursiveGTLS, run

    rng = np.random.default_rng(0)
    for n in counts:
        A = rng.normal(size=(50, n))
        run("RRLM", A, A.sum(axis=1))
    for n in gtls_counts:
        A = rng.normal(size=(50, n))
        run(RecursiveGTLS(n), A, A.sum(axis=1))


def estimators_small() -> None:
    """The record loops for 1-3 parameters (RGTLS: 2-3) and the robust-weight ufunc (the road generator: the
    simulator group, which drives on a generated road)."""
    _record_loops(range(1, 4), range(2, 4))


def estimators_large() -> None:
    """The record loops for 4-6 parameters (RGTLS: 4) and the independent test world's kernels."""
    import numpy as np

    from roadload.experiments.worlds import independent

    _record_loops(range(4, 7), range(4, 5))
    independent.simulate_trip("city", 3, np.random.default_rng(1), 20.0)


#: the longest first (CPU seconds on a clean clone: gym 69, estimators_large 62, estimators_small 58 with the road
#: generator, simulator 32 without it), so that the two processes end close together: the two longest start at once,
#: each of the two shorter follows one of them
GROUPS: dict[str, Callable[[], None]] = {"gym": gym, "estimators_large": estimators_large,
                                          "estimators_small": estimators_small, "simulator": simulator}


def run_groups(jobs: int) -> int:
    """Every group in its own process, ``jobs`` at a time; the per-group wall and CPU seconds printed."""
    pending = list(GROUPS)
    running: dict[int, tuple[str, float]] = {}
    failed = []
    t0 = time.perf_counter()
    while pending or running:
        while pending and len(running) < max(1, jobs):
            name = pending.pop(0)
            proc = subprocess.Popen([sys.executable, __file__, "--group", name])
            running[proc.pid] = (name, time.perf_counter())
        pid, status, usage = os.wait4(-1, 0)
        if pid not in running:
            continue
        name, start = running.pop(pid)
        code = os.waitstatus_to_exitcode(status)
        print(f"{'ok' if code == 0 else f'FAILED (exit {code})'}: {name} kernels "
              f"({time.perf_counter() - start:.0f} s, {usage.ru_utime + usage.ru_stime:.0f} s CPU)", flush=True)
        if code:
            failed.append(name)
    print(f"kernels warmed in {time.perf_counter() - t0:.0f} s ({len(failed)} groups failed)")
    return 1 if failed else 0


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--group", choices=sorted(GROUPS), help="one group, in this process")
    ap.add_argument("--jobs", type=int, default=2, help="groups at a time (2: the CI machine's cores)")
    args = ap.parse_args(argv)
    if args.group:
        GROUPS[args.group]()
        return 0
    return run_groups(args.jobs)


if __name__ == "__main__":
    sys.exit(main())
