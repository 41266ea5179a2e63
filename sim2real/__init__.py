"""roadload.sim2real — where a simulator departs from recorded trips, which unmodelled effect explains it, and how
much of the gap disappears once the effect is switched on in the simulator.

- :func:`diagnose` (recorded trips, :class:`SimConfig`, :class:`DiagnosisSettings`) -> :class:`Diagnosis`;
  :func:`write_report` writes ``report.md``, ``diagnosis.json`` and PNG figures;
- the candidate catalog: :class:`CandidateEffect`, :func:`register_candidate`, :func:`candidate_names`;
- regimes: :class:`Regime`, :func:`register_regime`;
- the selftest on withheld effects: :func:`roadload.experiments.sim2real_selftest.run_selftest`.

Modules: ``forcemodel`` (the sim's force balance on the model registry), ``floor`` (the sim against its own trips),
``table`` (trips -> diagnosis table), ``energy`` (battery-power side), ``stats`` (block bootstrap, notches,
cluster covariance), ``regimes`` (localisation, eq. 3.4), ``reference`` (regime-only model), ``selection``
(split, CV, ΔAIC/ΔBIC, forward selection), ``gap`` and ``replay`` (gap measures), ``diagnose``, ``report``,
``selftest``, ``cli``.
"""

from .catalog import CandidateEffect, candidate_names, get_candidate, register_candidate
from .diagnose import Diagnosis, DiagnosisSettings, diagnose
from .errors import DiagnosisError
from .regimes import Regime, register_regime
from .report import write_report
from .simconfig import SimConfig

__all__ = ["CandidateEffect", "Diagnosis", "DiagnosisError", "DiagnosisSettings", "Regime", "SimConfig",
           "candidate_names", "diagnose", "get_candidate", "register_candidate", "register_regime",
           "write_report"]
