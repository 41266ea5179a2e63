"""Effect of EcoDrive-v0's speed shield on a trained policy: the same policy on the held-out roads with the shield
on and off (roadload.experiments.rl.shield_effect).

    python scripts/shield_effect.py --policy out/rl/ppo_ecodrive.zip   # saved by scripts/train_rl.py --out out/rl
    python scripts/shield_effect.py --quick                            # CI: full throttle, 1 road
"""

from roadload.experiments.rl.shield_effect import main

if __name__ == "__main__":
    main()
