"""Day-long trips in bounded memory: peak RSS and file size of a streamed simulation per simulated duration
(roadload.experiments.benchmarks.trip_storage).

    python scripts/bench_trip_storage.py                      # 1 h and 4 h
    python scripts/bench_trip_storage.py --hours 1 4 24       # + a day (~1 min CPU plus I/O)
    python scripts/bench_trip_storage.py --quick              # CI smoke run (< 60 s): 5 and 10 min
"""

from roadload.experiments.benchmarks.trip_storage import main

if __name__ == "__main__":
    main()
