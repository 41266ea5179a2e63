"""Where one batch step of the native vector env spends its CPU time: the compiled step, the autoreset episode
setups and the rest of step() in Python (roadload.experiments.benchmarks.vector_env_profile).

    python scripts/profile_vector_env.py [--threads 1] [--steps 3000] [--native 256]
    python scripts/profile_vector_env.py --quick                                         # CI smoke run
    PYTHONPATH=<exported old tree> python scripts/profile_vector_env.py                 # the same for an old commit
"""

from roadload.experiments.benchmarks.vector_env_profile import main

if __name__ == "__main__":
    main()
