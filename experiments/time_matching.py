"""Equal-trip-time comparison: find the MPC time weight lambda [J/s] whose closed-loop trip time matches a target.

Trip time falls monotonically with lambda, so the search brackets lambda on a log scale and then takes
secant/bisection steps in (log lambda, time) until |T - T_target| <= tol * T_target. Runs that miss the
tolerance within ``max_runs`` are returned flagged (``matched`` False) with the closest run, never silently.
:meth:`MatchedRun.energy_at_target` interpolates the energy to exactly the target time between bracketing runs.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable

from roadload.controllers.closed_loop import RunResult


@dataclass
class MatchedRun:
    result: RunResult
    time_weight: float
    target_time: float
    matched: bool
    runs: int
    history: list[tuple[float, float, float]] = field(default_factory=list)  # (lambda, trip time, energy J)

    def energy_at_target(self) -> float:
        """Source energy [J] interpolated linearly in trip time to exactly the target time between the two
        closest runs that bracket it; NaN when no run pair brackets the target."""
        runs = [(t, e) for _, t, e in self.history if math.isfinite(t) and math.isfinite(e)]
        above = [r for r in runs if r[0] >= self.target_time]
        below = [r for r in runs if r[0] <= self.target_time]
        if not above or not below:
            return float("nan")
        (t1, e1), (t2, e2) = min(above), max(below)
        if t1 == t2:
            return e1
        return e1 + (self.target_time - t1) * (e2 - e1) / (t2 - t1)

    @property
    def time_error(self) -> float:
        """(T - T_target) / T_target [-]."""
        return self.result.metrics["trip_time"] / self.target_time - 1.0


def match_trip_time(run: Callable[[float], RunResult], target_time: float, tol: float = 0.01,
                    lam0: float = 8000.0, lam_min: float = 50.0, lam_max: float = 2e6,
                    max_runs: int = 10) -> MatchedRun:
    """Closed-loop runs ``run(lambda)`` until the trip time is within ``tol`` of ``target_time`` [s]."""
    if not target_time > 0 or not math.isfinite(target_time):
        raise ValueError(f"target_time must be a positive finite number, got {target_time}")
    if not 0 < tol < 1:
        raise ValueError(f"tol must be in (0, 1), got {tol}")
    history: list[tuple[float, RunResult]] = []

    def evaluate(lam: float) -> float:
        res = run(lam)
        history.append((lam, res))
        t = res.metrics["trip_time"]
        return t if math.isfinite(t) else float("inf")

    def done(t: float) -> bool:
        return abs(t / target_time - 1.0) <= tol

    lo, hi = None, None  # (log lam, time) with time above / below the target
    lam = lam0
    t = evaluate(lam)
    while not done(t) and len(history) < max_runs:
        x = math.log(lam)
        if t > target_time:
            lo = (x, t)
        else:
            hi = (x, t)
        if lo is None or hi is None:  # expand the bracket by a factor 4 in lambda
            x_new = x + (math.log(4.0) if hi is None else -math.log(4.0))
            if not math.log(lam_min) <= x_new <= math.log(lam_max):
                break
        else:
            (x1, t1), (x2, t2) = lo, hi
            x_new = x1 + (target_time - t1) * (x2 - x1) / (t2 - t1) if math.isfinite(t1) else 0.5 * (x1 + x2)
            span = x2 - x1
            x_new = min(max(x_new, x1 + 0.1 * span), x2 - 0.1 * span)  # safeguard: stay inside the bracket
        lam = math.exp(x_new)
        t = evaluate(lam)
    best_lam, best = min(history, key=lambda h: abs(h[1].metrics["trip_time"] / target_time - 1.0)
                         if math.isfinite(h[1].metrics["trip_time"]) else float("inf"))
    ok = math.isfinite(best.metrics["trip_time"]) and done(best.metrics["trip_time"])
    trace = [(lam_i, r.metrics["trip_time"], r.metrics["energy_J"]) for lam_i, r in history]
    return MatchedRun(best, best_lam, target_time, ok, len(history), trace)
