"""Test worlds for the sim-to-real selftest that share no physics code with ``roadload.envs``.

- ``fastsim``: NREL's FASTSim 3 drives its own vehicle (:mod:`.fastsim_world`);
- ``independent``: a chapter-2 longitudinal + lateral model written for the test (:mod:`.independent`).

:func:`generate_case` writes a case (100 Hz CSV logs, mapping JSON, matched roadload vehicle JSON, truth);
:func:`run_world_selftest` runs the existing diagnosis on the worlds and gives the confusion tables.
"""

from .cases import WORLDS, generate_case, not_expressible, supported_effects
from .common import NONE, OUTSIDE, Withheld, WorldCase, WorldError
from .selftest import (
           WorldResult,
           WorldSelftest,
           default_settings,
           diagnose_case,
           run_world_selftest,
)

__all__ = ["NONE", "OUTSIDE", "WORLDS", "Withheld", "WorldCase", "WorldError", "WorldResult", "WorldSelftest",
           "default_settings", "diagnose_case", "generate_case", "not_expressible", "run_world_selftest",
           "supported_effects"]
