"""Benchmarks: speed of the simulator, the estimators, the gym environments (and where a vector-env step spends
its time; EcoTraffic-v0 against highway-env in :mod:`.traffic`), the MPC, log import, trip storage, the command
line's start-up and the chapter-5 fleet run; the bitwise identity checks of the simulator core and of the
estimators against another commit; and the old/new export behind every ``--compare`` / ``--ref``
(:mod:`.refcompare`). Each module's ``main(argv)`` is what ``scripts/bench_*.py`` call. Speed figures are ratios
against a reference measured in the same run."""
