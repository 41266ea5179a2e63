"""Day-long trips in bounded memory: peak RSS and file size of a streamed simulation (``simulate(out=...)`` =
``roadload simulate``) per simulated duration, each run in a child process (its own peak RSS from wait4), plus
the same for the in-memory path (``simulate()`` + ``Trip.save``) at the shortest duration for reference.

Figures: peak RSS [MB] per duration and its growth per simulated hour; file size [MB] per simulated hour (100 Hz,
every channel and the truth) of the open format ('compact': plain SI floats, Parquet's own encodings; the target is
<= 15 MB per hour) next to the earlier private integer codec ('packed', format 3) and 'exact' (float64); the import
+ road baseline RSS (a child that stops before simulating).

    python scripts/bench_trip_storage.py                      # 1 h and 4 h
    python scripts/bench_trip_storage.py --hours 1 4 24       # + a day (~1 min CPU plus I/O)
    python scripts/bench_trip_storage.py --quick              # CI smoke run (< 60 s): 5 and 10 min
"""

import argparse
import os
import subprocess
import sys
import tempfile
import time

CHILD = r"""
import sys, time
from roadload.envs.simulator import simulate
from roadload.road_profiles import load_profile
mode, seconds, out, precision = sys.argv[1], float(sys.argv[2]), sys.argv[3], sys.argv[4]
road = load_profile("motorway", seed=0, length=max(40.0 * seconds, 2000.0))  # never runs out of road
if mode == "baseline":  # everything but the simulation: imports, the road, the simulator built on it
    from roadload.envs.simulator import Simulator
    Simulator("bmw_i3", road, seed=1)
    sys.exit(0)
t0 = time.process_time()
if mode == "stream":
    simulate("bmw_i3", road, seed=1, duration=seconds, out=out, precision=precision)
else:
    simulate("bmw_i3", road, seed=1, duration=seconds).save(out, precision=precision)
print(time.process_time() - t0)
"""


def run_child(mode: str, seconds: float, out: str, precision: str) -> tuple[float, float, float]:
    """(peak RSS [MB], CPU seconds of the simulation, file size [MB]) of one child process."""
    proc = subprocess.Popen([sys.executable, "-c", CHILD, mode, str(seconds), out, precision],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    _, status, usage = os.wait4(proc.pid, 0)
    if proc.stdout is None or proc.stderr is None:  # both are pipes (Popen above); this narrows their type
        raise RuntimeError("run_child: the child's output pipes are missing")
    stdout, stderr = proc.stdout.read(), proc.stderr.read()
    proc.returncode = os.waitstatus_to_exitcode(status)
    if proc.returncode != 0:
        raise SystemExit(f"child {mode} {seconds:g} s failed:\n{stderr[-2000:]}")
    size = os.path.getsize(out) / 1e6 if os.path.exists(out) else float("nan")
    cpu = float(stdout.strip().splitlines()[-1]) if stdout.strip() else 0.0
    return usage.ru_maxrss / 1024.0, cpu, size


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--hours", type=float, nargs="+", default=[1.0, 4.0], help="simulated durations [h]")
    ap.add_argument("--quick", action="store_true", help="tiny run for CI: 5 and 10 simulated minutes")
    ap.add_argument("--no-exact", action="store_true", help="skip the precision='exact' and 'packed' file-size rows")
    args = ap.parse_args(argv)
    hours = [5 / 60, 10 / 60] if args.quick else sorted(args.hours)
    if args.quick:
        args.no_exact = True
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        out = os.path.join(tmp, "trip.parquet")
        base, _, _ = run_child("baseline", 3600.0 * hours[-1], out, "compact")
        print(f"baseline (imports + road + simulator of the longest run, no simulation): peak RSS {base:.0f} MB")
        t_wall = time.perf_counter()
        for h in hours:
            rss, cpu, size = run_child("stream", 3600.0 * h, out, "compact")
            rows.append(("stream, compact", h, rss, cpu, size))
            print(f"streamed {h:6.2f} h: peak RSS {rss:7.0f} MB (baseline + {rss - base:.0f} MB), {cpu:6.1f} s CPU, "
                  f"file {size:7.1f} MB "
                  f"({size / h:5.1f} MB per simulated hour, open format 'compact')", flush=True)
        h0 = hours[0]
        if not args.no_exact:
            for precision, what in (("packed", "the earlier private integer codec (format 3)"),
                                    ("exact", "float64, bit for bit")):
                rss, cpu, size = run_child("stream", 3600.0 * h0, out, precision)
                rows.append((f"stream, {precision}", h0, rss, cpu, size))
                print(f"streamed {h0:6.2f} h, precision {precision}: file {size:7.1f} MB ({size / h0:5.1f} MB per "
                      f"hour; {what})")
        rss, cpu, size = run_child("memory", 3600.0 * h0, out, "exact")
        rows.append(("in memory, exact", h0, rss, cpu, size))
        print(f"in-memory simulate() + save {h0:6.2f} h: peak RSS {rss:7.0f} MB (the path before streaming)")
        print(f"total wall time {time.perf_counter() - t_wall:.0f} s")
    stream = [r for r in rows if r[0] == "stream, compact"]
    if len(stream) > 1:
        (_, h1, r1, _, _), (_, h2, r2, _, _) = stream[0], stream[-1]
        print(f"peak RSS growth: {(r2 - r1) / (h2 - h1):.1f} MB per simulated hour "
              f"({h1:g} h -> {h2:g} h: {r1:.0f} -> {r2:.0f} MB); extrapolated to 24 h: "
              f"{r1 + (r2 - r1) / (h2 - h1) * (24 - h1):.0f} MB")
