"""Simulator speed: simulated seconds per wall-clock (and CPU) second at 100 Hz with all sensors and effects on,
peak memory of that run, step-API throughput, and the compiled core alone against a hand-written reference loop.

    python scripts/bench_simulator.py [--duration 3600] [--repeats 3] [--quick]
    python scripts/bench_simulator.py --compare main [--rounds 3] [--quick]

Core figure: substeps per CPU-second of ``Simulator.run`` (built-in driver, every effect but the scheduled ramps,
the truth log written, no Trip built) from a reset simulator, divided by the rate of a hand-written compiled
point-mass loop (road-load equations 2.5-2.10, a PI speed controller, a 6-channel log) measured in the same run: a
machine-independent ratio. ``--compare REF`` exports commit REF (``git archive``) into a temporary package tree and
runs this module on it and on the working tree, interleaved ``--rounds`` times, and prints old/new ratios of the
core and trip figures.

Target: >= 1000x real time, i.e. a one-hour trip in under 3.6 s on one core. ``roadload benchmark simulator``
prints :func:`report`. This file runs against an old package tree too (``--compare``): it imports from roadload
only what every commit has.
"""

from __future__ import annotations

import argparse
import json
import math
import resource
import statistics
import time
import tracemalloc
import warnings
from pathlib import Path

import numpy as np
from numba import njit

from roadload.envs import EFFECTS, Simulator
from roadload.envs.simulator import Action, LateralValidityWarning, simulate
from roadload.road_profiles import load_profile
from roadload.units import STANDARD_AIR_DENSITY, G


def _road(length: float, seed: int):

    return load_profile("motorway", seed=seed, length=length)


def trip_speed(duration: float = 3600.0, vehicle: str = "gt_rwd", repeats: int = 3, seed: int = 1) -> dict:
    """Best-of-``repeats`` wall and CPU time of ``simulate`` (all effects incl. sensor faults, default sensors)
    for ``duration`` simulated seconds, including building the Trip; plus peak memory of one run."""
    road = _road(max(60_000.0, duration * 45.0), seed)
    simulate(vehicle, road, effects="all", seed=seed, duration=10.0)  # compile / load the numba cache
    walls, cpus = [], []
    for r in range(repeats):
        w0, c0 = time.perf_counter(), time.process_time()
        trip = simulate(vehicle, road, effects="all", seed=seed + r, duration=duration)
        walls.append(time.perf_counter() - w0)
        cpus.append(time.process_time() - c0)
    if trip.truth is None:
        raise ValueError(f"simulate({vehicle!r}) returned a trip without ground-truth channels; cannot count samples")
    sim_s = trip.duration
    n_rows = len(trip.truth)
    del trip
    tracemalloc.start()
    trip = simulate(vehicle, road, effects="all", seed=seed, duration=duration)
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    n_truth = 0 if trip.truth is None else trip.truth.shape[1] - 1
    return {"vehicle": vehicle, "simulated_s": sim_s, "samples": n_rows, "measured_channels": len(trip.channels),
            "truth_channels": n_truth, "wall_s": min(walls), "cpu_s": min(cpus),
            "realtime_factor_wall": sim_s / min(walls), "realtime_factor_cpu": sim_s / min(cpus),
            "peak_traced_MB": peak / 1e6, "max_rss_MB": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e3}


def step_speed(n_steps: int = 20000, n_substeps: int = 10, vehicle: str = "bmw_i3", seed: int = 1) -> dict:
    """Step-API throughput [steps/s] for Action commands, signed forces, and observe() cost [us]."""

    sim = Simulator(vehicle, load_profile("hilly", seed=seed), seed=seed)
    out = {}
    warnings.simplefilter("ignore", LateralValidityWarning)  # constant traction overshoots some curves
    for label, action in (("action", Action(traction_force=600.0)), ("signed_force", 300.0), ("driver", None)):
        sim.reset()
        sim.step(action, n_substeps)
        c0 = time.process_time()
        for _ in range(n_steps):
            if sim.step(action, n_substeps).done:
                sim.reset()
        out[f"steps_per_s_{label}"] = n_steps / (time.process_time() - c0)
    c0 = time.process_time()
    for _ in range(2000):
        sim.observe()
    out["observe_us"] = (time.process_time() - c0) / 2000 * 1e6
    c0 = time.process_time()
    for _ in range(2000):
        sim.true_parameters()
    out["true_parameters_us"] = (time.process_time() - c0) / 2000 * 1e6
    return out


def report(duration: float = 3600.0, repeats: int = 3) -> str:
    lines = []
    for vehicle in ("gt_rwd", "bmw_i3"):
        r = trip_speed(duration, vehicle, repeats)
        lines.append(f"{vehicle}: {r['simulated_s']:.0f} s simulated at 100 Hz ({r['samples']} samples, "
                     f"{r['measured_channels']} measured + {r['truth_channels']} truth channels, all effects)")
        lines.append(f"  wall {r['wall_s']:.2f} s -> {r['realtime_factor_wall']:.0f}x real time; "
                     f"CPU {r['cpu_s']:.2f} s -> {r['realtime_factor_cpu']:.0f}x real time (best of {repeats})")
        lines.append(f"  peak traced memory {r['peak_traced_MB']:.0f} MB, process max RSS {r['max_rss_MB']:.0f} MB")
    s = step_speed()
    lines.append("step API (bmw_i3, 10 substeps = 0.1 s per step, CPU time): "
                 + ", ".join(f"{k} {v:.0f}" for k, v in s.items()))
    return "\n".join(lines)


@njit(cache=True)
def reference_loop(n, dt, mass, cxa, f_r, v_set, log):
    """Hand-written reference: point-mass longitudinal model with a PI speed controller (eq. 2.5-2.10 road load,
    sinusoidal grade), explicit Euler at dt [s], one 6-channel log row per step. Returns the final speed."""
    g = G
    v = 0.0
    s = 0.0
    integ = 0.0
    for i in range(n):
        theta = 0.03 * math.sin(s / 400.0)
        f_cl = mass * g * math.sin(theta)
        f_roll = f_r * mass * g * math.cos(theta) * math.tanh(v / 0.1)
        f_aero = 0.5 * STANDARD_AIR_DENSITY * cxa * v * v
        err = v_set - v
        integ += err * dt
        f_drive = mass * (0.8 * err + 0.05 * integ)
        f_drive = min(max(f_drive, -8000.0), 6000.0)
        a = (f_drive - f_cl - f_roll - f_aero) / mass
        v = max(0.0, v + a * dt)
        s += v * dt
        j = i % log.shape[1]
        log[0, j] = i * dt
        log[1, j] = s
        log[2, j] = v
        log[3, j] = a
        log[4, j] = f_drive
        log[5, j] = f_aero + f_roll + f_cl
    return v


def reference_rate(n: int, repeats: int) -> float:
    """Best substeps per CPU-second of :func:`reference_loop`."""
    log = np.zeros((6, n))
    reference_loop(10, 0.01, 1500.0, 0.6, 0.01, 25.0, log)
    best = 0.0
    for _ in range(repeats):
        c0 = time.process_time()
        reference_loop(n, 0.01, 1500.0, 0.6, 0.01, 25.0, log)
        best = max(best, n / max(time.process_time() - c0, 1e-9))
    return best


SCHEDULED = ("wind_ramp", "mass_ramp", "drag_area_ramp", "rolling_resistance_ramp")


def core_rate(vehicle: str, n: int, repeats: int) -> float:
    """Best substeps per CPU-second of the compiled core through ``Simulator.run`` (built-in driver, every effect but
    the scheduled ramps) for n substeps from the same reset state every repeat."""
    effects = [name for name in EFFECTS if name not in SCHEDULED]
    sim = Simulator(vehicle, load_profile("motorway", seed=1, length=max(60_000.0, n * 0.45)), effects=effects,
                    seed=1, log_capacity=n + 1)
    best = 0.0
    for r in range(repeats + 1):  # the first run compiles / loads the cache
        sim.reset()
        c0 = time.process_time()
        sim.run(duration=n * 0.01)
        cpu = time.process_time() - c0
        if r:
            best = max(best, round(float(sim.state.t) / 0.01) / max(cpu, 1e-9))
    return best


def measure(duration: float, repeats: int, core_substeps: int) -> dict:
    """All figures of one run (JSON-able)."""
    warnings.simplefilter("ignore", LateralValidityWarning)
    ref = reference_rate(core_substeps, repeats)
    out: dict = {"reference_substeps_per_s": ref}
    for vehicle in ("gt_rwd", "bmw_i3"):
        core = core_rate(vehicle, core_substeps, repeats)
        trip = trip_speed(duration, vehicle, repeats)
        out[vehicle] = {"core_substeps_per_s": core, "core_over_reference": core / ref,
                        "trip_realtime_factor_cpu": trip["realtime_factor_cpu"],
                        "trip_realtime_factor_wall": trip["realtime_factor_wall"],
                        "trip_over_reference": trip["realtime_factor_cpu"] * 100.0 / ref,
                        "peak_traced_MB": trip["peak_traced_MB"], "samples": trip["samples"]}
    out["step_api"] = step_speed(n_steps=max(200, int(duration * 5)))
    return out


def print_figures(res: dict, duration: float, repeats: int) -> None:
    ref = res["reference_substeps_per_s"]
    print(f"hand-written reference loop (point mass, PI driver): {ref / 1e6:.2f} M substeps per CPU-second")
    for vehicle in ("gt_rwd", "bmw_i3"):
        r = res[vehicle]
        print(f"{vehicle}: core {r['core_substeps_per_s'] / 1e6:.3f} M substeps/s = {r['core_over_reference']:.4f} "
              f"x reference; trip of {duration:.0f} s ({r['samples']} samples, all effects and sensors): "
              f"{r['trip_realtime_factor_cpu']:.0f}x real time (CPU), {r['trip_realtime_factor_wall']:.0f}x (wall), "
              f"best of {repeats}; peak traced memory {r['peak_traced_MB']:.0f} MB")
    print("step API (bmw_i3, 10 substeps = 0.1 s per step, CPU time): "
          + ", ".join(f"{k} {v:.0f}" for k, v in res["step_api"].items()))


def print_comparison(old: list[dict], new: list[dict], ref: str) -> None:
    print(f"old = commit {ref}, new = working tree; {len(old)} interleaved rounds; figures relative to the "
          "hand-written reference loop of the same run; ratio new/old of the medians (> 1: new is faster)")
    print(f"{'figure':<44s} {'old':>10s} {'new':>10s} {'new/old':>8s}   per round new/old")
    for vehicle in ("gt_rwd", "bmw_i3"):
        for key in ("core_over_reference", "trip_over_reference"):
            o = [r[vehicle][key] for r in old]
            n = [r[vehicle][key] for r in new]
            rounds = " ".join(f"{b / a:.3f}" for a, b in zip(o, n))
            print(f"{vehicle + ' ' + key:<44s} {statistics.median(o):10.4f} {statistics.median(n):10.4f} "
                  f"{statistics.median(n) / statistics.median(o):8.3f}   {rounds}")


def main(argv: list[str] | None = None, repo: Path | None = None) -> None:
    """The benchmark's command line (``scripts/bench_simulator.py``); ``repo``: the git repository of
    ``--compare`` (default: the source tree of this file)."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--duration", type=float, default=3600.0, help="simulated seconds per trip run")
    ap.add_argument("--repeats", type=int, default=3, help="runs per figure (best is reported)")
    ap.add_argument("--core-substeps", type=int, default=200_000, help="substeps per core / reference run")
    ap.add_argument("--quick", action="store_true", help="tiny sizes for a smoke run (< 60 s)")
    ap.add_argument("--json", type=Path, help="also write the figures as JSON here")
    ap.add_argument("--compare", metavar="REF", help="git commit to compare against (in this run, interleaved)")
    ap.add_argument("--rounds", type=int, default=3, help="interleaved rounds of --compare")
    args = ap.parse_args(argv)
    if args.quick:
        args.duration, args.repeats, args.core_substeps = 60.0, 2, 20_000
    if args.compare:
        # imported here, not at the top: this file also runs against old package trees that lack the module
        from roadload.experiments.benchmarks.refcompare import REPO, compare

        git_repo = repo or REPO
        sub = ["--duration", str(args.duration), "--repeats", str(args.repeats),
               "--core-substeps", str(args.core_substeps)]
        old, new = compare(Path(__file__).resolve(), sub, args.compare, args.rounds, git_repo)
        print_comparison(old, new, args.compare)
        return
    res = measure(args.duration, args.repeats, args.core_substeps)
    print_figures(res, args.duration, args.repeats)
    if args.json:
        args.json.write_text(json.dumps(res))


if __name__ == "__main__":
    main()
