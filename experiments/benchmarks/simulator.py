"""Simulator speed benchmark: simulated seconds per wall-clock / CPU second at 100 Hz with all sensors and
effects on, peak memory, and step-API throughput. Used by ``scripts/bench_simulator.py`` and
``roadload benchmark simulator``."""

from __future__ import annotations

import resource
import time
import tracemalloc
import warnings

import numpy as np

from roadload.envs.simulator import Action, LateralValidityWarning, Simulator, simulate
from roadload.road_profiles import load_profile


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


if __name__ == "__main__":  # pragma: no cover
    np.set_printoptions(precision=3)
    print(report())
