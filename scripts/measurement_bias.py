"""Measurement-side honesty: the online M4-RRLM estimate against the least-squares fit of M4 to the simulator's
true forces, with the CAN drive-torque bias and the body pitch in eq. 5.2 switched off one by one
(roadload.experiments.measurement_bias).

    python scripts/measurement_bias.py [--out DIR] [--seeds 3] [--length 20000] [--quick]
"""

from roadload.experiments.measurement_bias import main

if __name__ == "__main__":
    main()
