"""Mutation score per pure-Python core module: mutmut, one module at a time, against its targeted tests
(roadload.experiments.mutation).

    python scripts/mutation_score.py                               # every module (long: nice, in the background)
    python scripts/mutation_score.py --module core/road_load.py --survivors
    python scripts/mutation_score.py --quick
"""

from roadload.experiments.mutation import main

if __name__ == "__main__":
    main()
