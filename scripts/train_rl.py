"""Train PPO and SAC (stable-baselines3) on roadload/EcoDrive-v0 with vectorised envs, save the policies, plot the
learning curve and evaluate on held-out roads against cruise control and the MPC.

    python scripts/train_rl.py --timesteps 300000 --out out/rl            # = roadload train ...
    python scripts/train_rl.py --evaluate-only --out out/rl               # re-evaluate saved policies
    python scripts/train_rl.py --quick                                    # tiny run for CI (PPO, 2k steps,
                                                                          # into out/rl_quick unless --out)

All options: python scripts/train_rl.py --help (the same as ``roadload train``).
"""

import sys

from roadload.experiments.cli import main

QUICK = ["--algo", "ppo", "--timesteps", "2048", "--eval-every", "0", "--held-out", "1", "--baselines", "cruise"]

if __name__ == "__main__":
    args = sys.argv[1:]
    if "--quick" in args:
        args = [a for a in args if a != "--quick"]
        if "--out" not in args:
            args += ["--out", "out/rl_quick"]
        args = QUICK + args
    sys.argv = ["roadload", "train", *args]
    main()
