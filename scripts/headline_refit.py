"""Re-summarise stored headline runs (runs.json of ``roadload benchmark headline``) with the current joint local
fit, plus the matching statistics of the truck time knob (roadload.experiments.headline_refit).

    python scripts/headline_refit.py RUNS.json [--out DIR]
    python scripts/headline_refit.py --quick   # the tiny headline's ./headline_quick/runs.json (run if absent)
"""

from roadload.experiments.headline_refit import main

if __name__ == "__main__":
    main()
