"""The base gap of a test world: with nothing withheld, how far the matched roadload vehicle's force balance plus
the sim's floor (what the diagnosis compares against) stays from the world's logged tractive force, per speed bin.

Per world (nothing withheld, seed 0, 3 trips): F_xV,measured - F_xV,sim [N] by speed bin, split into the analytic
balance's part (``raw``: measured - balance), the sim floor's (``floor``) and what is left (``residual``), for

- ``before``: the sim at roadload's default 20 °C ambient, floor fitted by plain least squares (rcond 1e-8) —
  the state the issue-13 gap of 20-30 N was measured in;
- ``ambient``: the matched sim config (the world's nominal ambient), the old floor fit;
- ``after``: the matched sim config and the floor's truncated-SVD fit (:data:`roadload.sim2real.floor.RCOND`).

    python scripts/worlds_base_gap.py --world independent,fastsim [--duration 900] [--seed 0]
    python scripts/worlds_base_gap.py --quick          # CI smoke run: independent, 240 s trips
"""

from roadload.experiments.worlds.base_gap import main

if __name__ == "__main__":
    raise SystemExit(main())
