"""Speed and findings of the chapter-5 fleet benchmark: generates the simulated fleet into a cache folder when
absent, runs the whole benchmark from the stored trips and prints the time split, the k = 900 MEDSE table and the
findings of the text (roadload.experiments.benchmarks.fleet).

    python scripts/bench_fleet.py [--trips 84] [--workers 2] [--scheduler ADDR] [--cache DIR] [--out DIR]
    python scripts/bench_fleet.py --quick      # CI smoke run: 3 trips in a temporary cache
"""

from roadload.experiments.benchmarks.fleet import main

if __name__ == "__main__":
    main()
