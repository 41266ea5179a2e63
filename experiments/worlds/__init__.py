"""Test worlds for the sim-to-real selftest that share no physics code with ``roadload.envs``.

- ``fastsim``: NREL's FASTSim 3 drives its own vehicle (:mod:`.fastsim_world`);
- ``independent``: a chapter-2 longitudinal + lateral model written for the test (:mod:`.independent`).

:func:`generate_case` writes a case (100 Hz CSV logs, mapping JSON, matched roadload vehicle JSON, truth); the
selftest that diagnoses them is :func:`roadload.experiments.sim2real.selftest.run_world`.
"""

from .cases import WORLDS, generate_case, not_expressible, supported_effects
from .common import NONE, OUTSIDE, Withheld, WorldCase, WorldError

__all__ = ["NONE", "OUTSIDE", "WORLDS", "Withheld", "WorldCase", "WorldError", "generate_case", "not_expressible",
           "supported_effects"]
