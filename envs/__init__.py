"""roadload.envs: the vehicle simulator (physics of ch. 2, drive-train eq. 2.17, effects, CAN sensors, driver).

Whole trips
-----------
``simulate(vehicle, road, effects=None, sensors=None, seed=0, duration=None, distance=None, driver=None,
progress=None, initial_speed=0.0) -> Trip``
    vehicle: a ``VehicleSpec`` (``roadload.vehicle``) or a preset name (``get_preset``: "gt_rwd", "gt_awd",
    "bmw_i3"); road: a ``RoadProfile`` or a ``DriveCycle`` (straight road along the cycle); effects: an
    ``EffectsConfig``, a list like ``["wind:mean_speed=5", "payload"]``, a string or None (see ``EFFECTS``);
    sensors: a ``SensorSpec`` (default: the vehicle's); driver: ``DriverConfig`` (built-in speed-tracking driver
    with preview) or a ``DriveCycle`` to follow on the road; progress: callable(fraction in [0, 1]).
    The Trip holds 100 Hz measured channels (names/units: ``roadload.channels``), the truth frame (true tractive
    force, mass, f_r, drag area, air density, grade, curvature, bank, wind, cornering stiffness, gear, engine
    state, brake friction, oil temperature, ...) and meta {"source": "sim", "vehicle", "road", "seed", "effects",
    "sample_rate", "driver", "sensors", "energy" (ledger [J]), "warnings"}.

Step API (used by the MPC and the gym environments; stable)
-----------------------------------------------------------
``sim = Simulator(vehicle, road, effects=None, sensors=None, seed=0, driver=None, initial_speed=0.0)``
``sim.reset(seed=None, initial_speed=None) -> StepResult``   back to s = 0 (same road, effects, sensors)
``sim.step(action, n_substeps=10) -> StepResult``            n_substeps x 10 ms with a constant command:
    * ``Action(traction_force, regen_force, friction_brake_force, steer=None, gear=None)`` — forces [N] >= 0 at the
      wheels. Traction -> engine/motor torque in the current gear (exact inverse of the loss maps, clipped to the
      torque limits); regen -> negative motor torque within the regen limit (ICE: engine drag, fuel cut);
      friction -> brake pressures (nominal pad friction; the true one may drift). ``steer``: front wheel angle
      [rad] (None: the built-in steering law follows the road). ``gear``: requested gear (None: shift strategy;
      0: neutral for the ICE, zero motor torque "sailing" for the BEV).
    * a float: signed wheel force [N]; negative values go to regen first, then the friction brakes.
    * None: the built-in driver decides (speed limits, curves, stops, drive cycle).
``StepResult`` fields: t, s, v, a, gear, engine_speed, engine_torque, clutch, source_energy (this step: fuel [J]
    for ICE, battery [J] for BEV), source_energy_total, tractive_force, lateral_acceleration, grade, curvature,
    bank, speed_limit (road at s), done (end of road / cycle), mass (m_V with payload [kg]).
``sim.state``               the latest StepResult
``sim.vehicle_state``       the live state (``VehicleState``: time, position, speed, mass, gear, engine_speed, the
                            energy ledger, ... by name, SI; ``position`` and ``speed`` settable between steps)
``sim.parameters``          the packed vehicle / effect / driver parameters by name (``VehicleParameters``)
``sim.true_parameters()``   dict of the CURRENT true lumped parameters: mass, rolling_resistance_f0/f1/f4,
                            drag_area, air_density, aero_coefficient (rho/2 c_x A), wind_speed, wind_angle,
                            cornering_stiffness(_front/_rear), brake_friction_coefficient, drivetrain_loss_factor,
                            a/b/c (m g f_r0, m g f_r1, rho/2 c_x A), effective_mass, wheel_radius, grade, ...
``sim.regen_capacity()``    largest braking force [N] engine drag / regen can apply now
``sim.observe()``           the latest CAN-like sample (dict of measured channels, SI, + "t", "valid"); equal to
                            the same row of ``sim.to_trip().measured``
``sim.to_trip()``           the Trip of everything stepped since reset (measured + truth + meta)
``sim.run(duration=None, distance=None, progress=None)``  continue with the built-in driver
``sim.energy_ledger()``     cumulative energies [J]: source, shaft work, losses by component, climbing work, kinetic

Compiled batch step: ``roadload.envs.batch`` (``Fleet``: N vehicles advanced from another numba kernel through
packed records, the same core). ``Powertrain(spec)``: the simulator's drive-train (eq. 2.17) evaluated from Python.

Throughput (``scripts/bench_simulator.py``, CPU time on one core): a one-hour 100 Hz trip with all sensors and
effects in ~0.8 s (~4500x real time, ~430 MB peak); ``step`` with 10 substeps ~14 us (~70 000 steps/s);
``observe`` ~13 us. The first import compiles the jitted core (~20-40 s) into a cache under ``__pycache__``.
Effects: ``EFFECTS`` (names, equations, parameters with defaults); the scheduled ones (wind_ramp, mass_ramp,
drag_area_ramp, rolling_resistance_ramp: onset / ramp in time or distance) are applied by the core before every
substep (``schedules.py`` packs them) and show in the truth channels. Lateral accelerations above ~4 m/s^2 raise a
``LateralValidityWarning`` (single-track model validity, section 2.5.1).
"""

from .driver import DriverConfig
from .effects import EFFECTS, EffectsConfig, EffectsError, describe_effects
from roadload.presets import PRESETS, get_preset
from .sensors import SensorConfigError
from .powertrain import Powertrain
from .simulator import (
    TRUTH_LOG_COLUMNS, Action, LateralValidityWarning, SimulationError, Simulator, StepResult, simulate,
)
from .state import VehicleParameters, VehicleState

SensorConfig = __import__("roadload.vehicle", fromlist=["SensorSpec"]).SensorSpec  # alias: the sensor set

__all__ = ["Action", "DriverConfig", "EFFECTS", "EffectsConfig", "EffectsError", "LateralValidityWarning",
           "PRESETS", "Powertrain", "SensorConfig", "SensorConfigError", "SimulationError", "Simulator", "StepResult",
           "TRUTH_LOG_COLUMNS", "VehicleParameters", "VehicleState", "describe_effects", "get_preset", "simulate"]
