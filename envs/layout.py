"""Storage of the jitted simulator core (private to ``roadload.envs``): named record types and the log / road / table
layouts.

The numba core works on numpy structured records, one per vehicle, so that a kernel reads ``x.speed`` or
``p.wheel_radius`` instead of an index: ``VEHICLE`` = {``state``: STATE, ``params``: PARAMS, ``command``: COMMAND,
``road_points``, ``stop_count``}. Each field list below gives (name, SI unit, meaning) once; the dtypes are built
from it. Outside ``envs/`` the state is read through :class:`roadload.envs.VehicleState` and advanced through
:mod:`roadload.envs.batch`; an import-linter contract keeps this module private.

The truth log (one column per 10-ms substep, one row per channel: ``L_*``), the road attributes over distance
(``R_*`` rows) and the drive-train tables (``T_*``) stay flat float arrays with named row constants; numba freezes
them at compile time. :func:`_check_layout` verifies at import that the constants agree with their name lists.
"""

from __future__ import annotations

import re
from typing import NamedTuple

import numpy as np

MAX_GEARS = 12


def _table(text: str) -> tuple[tuple[str, str, str], ...]:
    """(name, unit, meaning) rows of a text table whose columns are separated by two or more spaces."""
    rows = tuple(tuple(re.split(r"\s{2,}", line.strip(), maxsplit=2)) for line in text.strip().splitlines())
    if any(len(row) != 3 or not row[0].isidentifier() for row in rows):
        raise RuntimeError(f"layout: a field table row is not 'name  unit  meaning': {rows}")
    return rows  # type: ignore[return-value]


# ---------------------------------------------------------------------------------------------------- state
STATE_FIELDS = _table("""
time                           s      trip time t
position                       m      distance s driven along the road
speed                          m/s    vehicle speed v >= 0
acceleration                   m/s^2  longitudinal acceleration of the last substep
log_rows                       -      truth-log rows written
gear                           -      engaged gear G (0: neutral)
clutch_mode                    -      clutch: 0 open, 1 slipping, 2 locked
engine_speed                   rad/s  engine / motor speed omega_E
slip_time                      s      time the clutch has been slipping
last_shift_time                s      time of the last gear change
engine_torque                  N m    engine / motor torque T_E
clutch_torque                  N m    clutch torque T_C
brake_pressure_front           Pa     front brake line pressure
brake_pressure_rear            Pa     rear brake line pressure
state_of_charge                -      battery state of charge (BEV)
side_slip_angle                rad    side-slip angle beta
yaw_rate                       rad/s  yaw rate r
wheel_steer_angle              rad    front wheel steer angle delta
lateral_offset                 m      lateral offset e_y to the road centre line
heading_error                  rad    heading error e_psi to the road
lateral_acceleration           m/s^2  lateral acceleration a_y
lateral_acceleration_peak      m/s^2  largest |a_y| so far (signed)
lateral_warning_count          -      substeps with |a_y| above the single-track validity limit
mass                           kg     vehicle mass m_V (incl. payload)
drag_area_factor               -      drag-area factor (roof box, windows, sunroof)
windows_open                   -      windows open (0/1)
sunroof_open                   -      sunroof open (0/1)
gust_speed                     m/s    wind gust speed deviation
wind_direction_deviation       rad    wind direction deviation
oil_temperature                K      gearbox oil temperature
brake_disc_temperature         K      brake disc temperature
pad_friction_walk              -      random walk of the brake pad friction coefficient
payload_stop_index             -      next stop where the payload may change
road_index                     -      road segment at the position (search start)
stop_index                     -      next stop line of the built-in driver
dwelling                       -      driver halted at a stop (0/1)
dwell_left                     s      time left at the stop
driver_integral                m/s^2  integral term of the driver's speed control
driver_speed_variation         m/s    driver's natural speed variation (Ornstein-Uhlenbeck)
driver_speed_variation_smooth  m/s    the speed variation low-passed (4 s)
driver_force                   N      driver's wheel-force demand after the pedal lag
source_energy                  J      fuel or battery energy used
shaft_work                     J      shaft work T_E omega_E
gearbox_loss                   J      gearbox dissipation
differential_loss              J      differential dissipation
clutch_loss                    J      clutch dissipation
brake_loss                     J      brake dissipation (incl. hold force)
rolling_loss                   J      rolling-resistance work
aero_loss                      J      aerodynamic drag work
cornering_loss                 J      cornering and toe-in resistance work
climbing_work                  J      climbing work
payload_potential_energy       J      potential energy of payload changes
mass_ramp_applied              kg     mass the mass_ramp schedule has added so far
""")
"""(name, unit, meaning) of every state field (float64), then ``random_state`` (uint64, the splitmix64 state)."""

STATE = np.dtype([(name, np.float64) for name, _, _ in STATE_FIELDS] + [("random_state", np.uint64)])

# ---------------------------------------------------------------------------------------------------- parameters
PARAM_FIELDS = _table("""
dt                              s            physics step
is_bev                          -            1: battery-electric, 0: combustion engine
driven_axle                     -            0 rear, 1 front, 2 all
n_gears                         -            number of gears
mass_nominal                    kg           vehicle mass without payload m_V,0 (ramped by mass_ramp)
wheelbase                       m            wheelbase l
cg_to_front                     m            centre of gravity to front axle l_12
cg_to_rear                      m            centre of gravity to rear axle l_34
yaw_inertia                     kg m^2       yaw inertia
track_front                     m            front track width
track_rear                      m            rear track width
pitch_gradient                  rad/(m/s^2)  body pitch per longitudinal acceleration
roll_gradient                   rad/(m/s^2)  body roll per lateral acceleration
wheel_radius                    m            dynamic wheel radius r_W
wheel_inertia_4                 kg m^2       inertia of the four wheels 4 I_W
rolling_f0                      -            rolling resistance f_r0
rolling_f1                      s/m          rolling resistance f_r1
rolling_f4                      s^4/m^4      rolling resistance f_r4
cornering_stiffness_front       N/rad        front axle cornering stiffness c_12
cornering_stiffness_rear        N/rad        rear axle cornering stiffness c_34
longitudinal_stiffness          N            tyre longitudinal slip stiffness c_xW
toe_in                          rad          toe-in angle delta_toe
drag_coefficient                -            drag coefficient c_w (ramped by drag_area_ramp)
frontal_area                    m^2          frontal area A_V
yaw_drag_factor                 -            drag increase with sin^2 of the yaw angle
final_drive                     -            final drive ratio i_D
differential_inertia            kg m^2       differential inertia I_D
clutch_inertia                  kg m^2       clutch inertia I_C
source_inertia                  kg m^2       engine / motor inertia I_E
idle_speed                      rad/s        engine idle speed
max_engine_speed                rad/s        engine / motor speed limit
max_torque                      N m          largest source torque
max_power                       W            motor power limit (BEV)
regen_torque_limit              N m          regeneration torque limit (BEV)
regen_power_limit               W            regeneration power limit (BEV)
upshift_speed_low               rad/s        upshift engine speed at zero load
upshift_speed_high              rad/s        upshift engine speed at full load
downshift_speed_low             rad/s        downshift engine speed at zero load
downshift_speed_high            rad/s        downshift engine speed at full load
shift_interval                  s            shortest time between shifts
sync_time_constant              s            engine speed governor time constant while slipping
max_slip_time                   s            clutch locks after slipping this long
launch_speed                    rad/s        engine speed during launch
lock_slip_speed                 rad/s        clutch locks below this slip speed
oil_warm_temperature            K            warm gearbox oil temperature
oil_cold_loss_factor            -            loss factor phi of cold oil
oil_time_constant               s            oil warm-up time constant
battery_capacity                J            battery capacity
battery_open_circuit_voltage    V            battery open-circuit voltage
battery_resistance              ohm          battery internal resistance
auxiliary_power                 W            auxiliary power (BEV)
brake_area_front                m^2          front brake piston area
brake_area_rear                 m^2          rear brake piston area
brake_radius_front              m            front brake effective radius
brake_radius_rear               m            rear brake effective radius
pad_friction                    -            nominal pad friction coefficient
brake_front_share               -            front share of the brake force
brake_pressure_max              Pa           largest brake line pressure
disc_heat_capacity              J/K          brake disc heat capacity
disc_cooling                    W/K          brake disc cooling at standstill
disc_cooling_speed              W s/(K m)    brake disc cooling per speed
brake_time_constant             s            brake pressure lag
ambient_temperature             K            ambient temperature T_a
ambient_pressure                Pa           ambient pressure p_a at zero elevation
wind_on                         -            effect 'wind' (0/1)
wind_mean_speed                 m/s          mean wind speed (ramped by wind_ramp)
wind_direction                  rad          wind direction (ramped by wind_ramp)
wind_gust_std                   m/s          gust speed standard deviation
wind_gust_time_constant         s            gust time constant
wind_direction_std              rad          wind direction standard deviation
payload_on                      -            effect 'payload' (0/1)
payload_change_std              kg           payload change at a stop (std)
payload_min                     kg           smallest payload
payload_max                     kg           largest payload
tire_warmup_on                  -            effect 'tire_warmup' (0/1)
tire_cold_factor                -            rolling-resistance factor of cold tyres
tire_warmup_distance            m            tyre warm-up distance constant
winter_tires_on                 -            effect 'winter_tires' (0/1)
winter_rolling_factor           -            winter-tyre rolling-resistance factor
winter_cornering_factor         -            winter-tyre cornering-stiffness factor
drag_area_on                    -            effect 'drag_area' (0/1)
drag_roof_box                   -            drag-area increase of the roof box
drag_windows                    -            drag-area increase with open windows
drag_sunroof                    -            drag-area increase with the sunroof open
drag_toggle_rate                1/h          window / sunroof toggles per hour
road_bank_on                    -            effect 'road_bank' (0/1)
bank_scale                      -            factor on the measured bank
superelevation_gain             rad m        design bank per curvature
bank_max                        rad          largest design bank
wet_road_on                     -            effect 'wet_road' (0/1)
wet_rolling_factor              -            wet-road rolling-resistance factor
wet_f1                          s/m          wet-road addition to f_r1
oil_temperature_on              -            effect 'oil_temperature' (0/1)
oil_start_temperature           K            oil temperature at the start
pad_drift_on                    -            effect 'brake_pad_drift' (0/1)
pad_temperature_coefficient     1/K          pad friction change per disc temperature
pad_reference_temperature       K            disc temperature of the nominal pad friction
pad_random_walk_std             1/s^0.5      pad friction random walk
barometric_on                   -            effect 'barometric' (0/1)
barometric_scale_height         m            barometric scale height
auxiliary_load_on               -            effect 'auxiliary_load' (0/1)
auxiliary_load                  W            additional auxiliary power
driver_lateral_acceleration     m/s^2        driver's lateral acceleration limit
driver_max_acceleration         m/s^2        driver's largest acceleration
driver_max_deceleration         m/s^2        driver's largest deceleration
driver_planning_deceleration    m/s^2        driver's planning deceleration
driver_speed_time_constant      s            driver's speed time constant
driver_integral_gain            1/s          driver's integral gain
driver_variation_std            m/s          driver's speed variation std
driver_variation_time_constant  s            driver's speed variation time constant
steering_lookahead_time         s            steering look-ahead time
steering_preview_time           s            steering curvature preview time
dwell_min                       s            shortest stop
dwell_max                       s            longest stop
driver_speed_margin             m/s          driver's margin below the plan
understeer_gradient             s^2/m        understeer gradient EG of the steering law
driver_air_density              kg/m^3       air density the driver assumes
pedal_time_constant             s            pedal / brake actuation time constant
steer_max                       rad          largest wheel steer angle
time_end                        s            run limit: trip time
distance_end                    m            run limit: position
road_length                     m            road length
cycle_mode                      -            1: follow the drive cycle, 0: the road
schedules_on                    -            1: a scheduled effect (ramp) is enabled
base_mass_nominal               kg           unscheduled nominal mass
base_drag_coefficient           -            unscheduled drag coefficient
base_rolling_f0                 -            unscheduled f_r0
base_rolling_f1                 s/m          unscheduled f_r1
base_rolling_f4                 s^4/m^4      unscheduled f_r4
""")
"""(name, unit, meaning) of every scalar parameter (float64)."""

RAMP = np.dtype([("on", np.float64), ("onset", np.float64), ("length", np.float64), ("by_distance", np.float64),
                 ("start", np.float64), ("final", np.float64)])
"""A scheduled quantity q = start + (final - start) clip((x - onset) / length, 0, 1), x = time [s] or position [m]
(``by_distance``); length 0: a step at the onset."""

RAMPS = ("ramp_wind_speed", "ramp_wind_direction", "ramp_mass", "ramp_drag", "ramp_rolling")

PARAMS = np.dtype([(name, np.float64) for name, _, _ in PARAM_FIELDS]
                  + [("gear_ratio", np.float64, (MAX_GEARS,)), ("gear_inertia", np.float64, (MAX_GEARS,))]
                  + [(name, RAMP) for name in RAMPS])
"""Scalar parameters, gear ratios i_G(G) [-] and gearbox inertias I_G(G) [kg m^2] of gears 1..12, ramps."""

# ---------------------------------------------------------------------------------------------------- command
COMMAND_FIELDS = _table("""
traction  N    traction force (signed wheel force in mode 2)
regen     N    regenerative braking force
friction  N    friction brake force
steer     rad  front wheel angle (NaN: built-in steering law)
gear      -    gear request (-1: shift strategy)
mode      -    0 explicit forces, 1 built-in driver, 2 signed wheel force
""")

COMMAND = np.dtype([(name, np.float64) for name, _, _ in COMMAND_FIELDS])
COMMAND_FORCES, COMMAND_DRIVER, COMMAND_WHEEL_FORCE = 0.0, 1.0, 2.0
"""Values of ``command.mode``."""

VEHICLE = np.dtype([("state", STATE), ("params", PARAMS), ("command", COMMAND), ("road_points", np.int64),
                    ("stop_count", np.int64)])
"""One vehicle of the core: state, parameters, held command, and the number of road points / stop lines of its
route (the used part of a fleet's padded road and stop arrays)."""


class Tables(NamedTuple):
    """The drive-train tables of a vehicle spec: ``values`` (float64, all curves and maps back to back) and
    ``descriptors`` (int64 (N_TABLES, 5): per table offset_x, n_x, offset_y, n_y, offset_values; numerics.py)."""

    values: np.ndarray
    descriptors: np.ndarray


class Route(NamedTuple):
    """What one vehicle drives on: ``road`` (N_ROAD rows over the distance grid, ``R_*``), ``stops`` (stop-line
    positions [m], increasing) and ``cycle`` (2 rows: time [s], speed [m/s] of a drive cycle to follow)."""

    road: np.ndarray
    stops: np.ndarray
    cycle: np.ndarray


def field_index(*path: str) -> int:
    """Position of a float64 field of VEHICLE in ``vehicle_array.view(np.float64)`` (e.g. ``("state", "speed")``):
    the Python side reads single fields through that view (a structured-field read costs 4x more)."""
    dtype, offset = VEHICLE, 0
    for name in path:
        if dtype.fields is None or name not in dtype.fields:
            raise KeyError(f"{'.'.join(path)}: no such field of the vehicle record")
        sub, off = dtype.fields[name][:2]
        dtype, offset = sub, offset + off
    if dtype != np.float64:
        raise KeyError(f"{'.'.join(path)}: not a float64 field")
    return offset // 8


# ---------------------------------------------------------------------------------------------------- log columns
LOG = [
    "T", "POS", "V", "A", "FX", "RIM", "MASS", "FR", "FR0", "FR1", "FR4", "CXA", "RHO", "GRADE", "CURV",
    "PATHCURV", "BANK", "WIND_S", "WIND_A", "CSF", "CSR", "TE", "WE", "GEAR", "CLUTCH", "PBF", "PBR", "MU",
    "AY", "ACC_X_SENS", "ACC_Y_SENS", "YAW", "BETA", "DELTA", "OIL", "LOSSF", "PSRC", "ESRC", "TAMB", "PAMB",
    "ELEV", "HEAD", "WFL", "WFR", "WRL", "WRR", "VBAT", "IBAT", "SOC", "FBRAKE", "FROLL", "FAERO", "FCLIMB",
    "FCORNER", "DRAGF", "DISC_T",
]
L_T = 0
L_POS = 1
L_V = 2
L_A = 3
L_FX = 4
L_RIM = 5
L_MASS = 6
L_FR = 7
L_FR0 = 8
L_FR1 = 9
L_FR4 = 10
L_CXA = 11
L_RHO = 12
L_GRADE = 13
L_CURV = 14
L_PATHCURV = 15
L_BANK = 16
L_WIND_S = 17
L_WIND_A = 18
L_CSF = 19
L_CSR = 20
L_TE = 21
L_WE = 22
L_GEAR = 23
L_CLUTCH = 24
L_PBF = 25
L_PBR = 26
L_MU = 27
L_AY = 28
L_ACC_X_SENS = 29
L_ACC_Y_SENS = 30
L_YAW = 31
L_BETA = 32
L_DELTA = 33
L_OIL = 34
L_LOSSF = 35
L_PSRC = 36
L_ESRC = 37
L_TAMB = 38
L_PAMB = 39
L_ELEV = 40
L_HEAD = 41
L_WFL = 42
L_WFR = 43
L_WRL = 44
L_WRR = 45
L_VBAT = 46
L_IBAT = 47
L_SOC = 48
L_FBRAKE = 49
L_FROLL = 50
L_FAERO = 51
L_FCLIMB = 52
L_FCORNER = 53
L_DRAGF = 54
L_DISC_T = 55

# ---------------------------------------------------------------------------------------------------- road rows
ROAD = ["S", "GRADE", "CURV", "BANK", "VLIM", "HEAD", "ELEV", "VPLAN", "CRUISE"]
R_S = 0
R_GRADE = 1
R_CURV = 2
R_BANK = 3
R_VLIM = 4
R_HEAD = 5
R_ELEV = 6
R_VPLAN = 7
R_CRUISE = 8

# ---------------------------------------------------------------------------------------------------- tables
TABLES = ["FULLLOAD", "DRAG", "FUEL", "MOTORLOSS", "DIFFLOSS", "STEER", "GBLOSS"]  # GBLOSS + (G-1) per gear
T_FULLLOAD = 0
T_DRAG = 1
T_FUEL = 2
T_MOTORLOSS = 3
T_DIFFLOSS = 4
T_STEER = 5
T_GBLOSS = 6

N_LOG = len(LOG)
N_ROAD = len(ROAD)
N_TABLES = len(TABLES) - 1 + MAX_GEARS  # GBLOSS for up to MAX_GEARS gears

MODE_OPEN = 0
MODE_SLIP = 1
MODE_LOCKED = 2


def _check_layout() -> None:
    """Every name list entry has its constant at its position (an edit of one without the other fails here)."""
    for prefix, names in (("L_", LOG), ("R_", ROAD), ("T_", TABLES)):
        for i, name in enumerate(names):
            if globals().get(prefix + name) != i:
                raise RuntimeError(f"layout: {prefix + name} must be {i} (position in the name list)")
    if VEHICLE.itemsize % 8:
        raise RuntimeError("layout: VEHICLE must be a whole number of float64 words")


_check_layout()
