"""roadload.sim2real — where a simulator departs from recorded trips, which unmodelled effect explains it, and how
much of the gap disappears once the effect is switched on in the simulator.

- :func:`diagnose` (recorded trips, :class:`SimConfig`, :class:`DiagnosisSettings`) -> :class:`Diagnosis`;
  :func:`write_report` writes ``report.md``, ``diagnosis.json`` and PNG figures;
- the candidate catalog: :class:`CandidateEffect`, :func:`register_candidate`, :func:`candidate_names`;
- regimes: :class:`Regime`, :func:`register_regime`;
- the selftest on withheld effects: :func:`roadload.experiments.sim2real.selftest.run_world`.

Recorded trips from a logger (``roadload diagnose --real FOLDER --format csv [--mapping FILE]``): the logs go
through :func:`roadload.io.import_log` exactly as with ``roadload import``; a folder yields the trip files of the
format only (``.csv`` for csv; mapping, vehicle or other JSON documents beside them are skipped). Without
``--mapping`` the csv format uses the packaged ``plain_csv`` mapping (``roadload/io/mappings/plain_csv.json``: a
``time_s`` column and one column per signal, e.g. ``speed_kmh``, ``accel_x_mps2``, ``drive_torque_nm``,
``brake_pressure_front_bar``). A mapping is JSON: ``format``, ``sample_rate`` [Hz], ``csv`` (``sep``, ``time``
column, ``time_unit``) and ``channels``, each ``{"source": header or [alternatives], "channel": Trip channel,
"unit": the column's unit, "scale"/"offset" (x = raw scale + offset, before the unit conversion), "resample":
linear | hold | nearest, "required": bool}`` (full schema: :mod:`roadload.io.mapping`). The diagnosis needs
``vehicle_speed``, ``accel_x`` and ``drive_torque`` (or ``rim_torque``); ``steering_wheel_angle`` gives the path
curvature, ``battery_voltage``/``battery_current`` the energy side. **Brake pressure** (``brake_pressure_front``,
``brake_pressure_rear``, wheel-cylinder pressure) becomes a friction-brake force only through the *sim vehicle's*
brake geometry, F_B = 2 (p_f A_f r_f + p_r A_r r_r) X_B / r_W (``brakes.front_area``, ``front_radius``,
``rear_area``, ``rear_radius``, ``pad_friction`` and ``wheel_radius`` of the vehicle JSON): a preset whose brakes
are not the car's shows up as a brake gain in the base block; it passes the same smoother as dv/dt. Without
brake pressure, braking samples are left out of the diagnosis.

Statistics (:mod:`.robust`, :mod:`.base`): the base calibration (mass, drag area, rolling resistance, drive-train
efficiency, brake gain, with standard errors) is reported first; candidates are ranked by a robust,
regime-normalised out-of-fold gain (braking rows judged only by brake candidates) and accepted only when the gain
beats a wild segment-bootstrap null at the family-wise level ``alpha``, is large enough (``min_size`` N RMS) and
maps to a physically plausible simulator setting (an implausible fit is reported, never an abort).

Modules: ``forcemodel`` (the sim's force balance on the model registry), ``floor`` (the sim against its own trips),
``table`` (trips -> diagnosis table), ``energy`` (battery-power side), ``stats`` (block bootstrap, notches,
cluster covariance), ``regimes`` (localisation, eq. 3.4), ``reference`` (regime-only model), ``selection``
(split, CV, ΔAIC/ΔBIC, forward selection), ``gap`` and ``replay`` (gap measures), ``diagnose`` (the pipeline of
named stages), ``results`` and ``records`` (its typed results), ``report``, ``robust`` (robust target, null
calibration), ``base`` (base calibration).
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
