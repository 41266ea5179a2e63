"""Index layout of the flat arrays the jitted simulator core works on.

The numba core (``physics.py``, ``driver.py``) takes a handful of flat float64 arrays instead of Python objects so
that one call costs a few microseconds: ``X`` (state), ``P`` (parameters), ``tabs`` + ``ti`` (lookup tables and
their descriptors), ``road`` (road attributes over distance), ``cmd`` (the command) and ``log`` (one row per
10-ms substep). The names below are module-level integer constants, which numba freezes at compile time.
"""

from __future__ import annotations

# ---------------------------------------------------------------------------------------------------- state X
STATE = [
    "T", "POS", "V", "A", "NLOG",
    # drive-train
    "GEAR", "MODE", "OMEGA_E", "SLIP_TIMER", "LAST_SHIFT", "TE", "TC", "PBF", "PBR", "SOC",
    # lateral
    "BETA", "YAW", "DELTA", "EY", "EPSI", "AY", "AY_MAX", "AY_WARN_N",
    # drifting quantities
    "MASS", "DRAGF", "WIN_OPEN", "SUN_OPEN", "GUST", "WIND_DIR_DEV", "OIL_T", "DISC_T", "MU_RW", "PAYLOAD_STOP",
    # road / driver bookkeeping
    "RIDX", "STOP_IDX", "DWELL", "DWELL_LEFT", "DRV_I", "DRV_VAR", "DRV_VAR2", "DRV_F", "CYC_IDX",
    # energy ledger (cumulative) [J]
    "E_SOURCE", "W_SHAFT", "D_GEARBOX", "D_DIFF", "D_CLUTCH", "D_BRAKE", "D_ROLL", "D_AERO", "D_CORNER", "W_CLIMB",
    "E_PAYLOAD_PE",
]

# ---------------------------------------------------------------------------------------------------- params P
PARAMS = [
    "DT", "KIND_BEV", "DRIVEN", "N_GEARS",
    # body / tires / aero
    "MASS0", "L", "LF", "LR", "IZ", "TRACK_F", "TRACK_R", "PITCH_GRAD", "ROLL_GRAD",
    "RW", "IW4", "FR0", "FR1", "FR4", "CF", "CR", "CX_SLIP", "TOE",
    "CW", "AREA", "YAW_DRAG",
    # drive-train
    "ID", "I_DIFF", "I_CLUTCH", "I_SOURCE", "IDLE", "MAX_SPEED", "MAX_TORQUE", "MAX_POWER", "REGEN_T", "REGEN_P",
    "UP_LO", "UP_HI", "DN_LO", "DN_HI", "SHIFT_MIN", "SYNC_TAU", "MAX_SLIP", "LAUNCH", "LOCK_SLIP",
    "OIL_WARM", "OIL_COLD_FACTOR", "OIL_TAU",
    "BAT_CAP", "BAT_VOC", "BAT_R", "AUX_P",
    # brakes
    "AB_F", "AB_R", "RB_F", "RB_R", "MU0", "BRAKE_SHARE", "P_MAX", "DISC_C", "DISC_H", "DISC_HV", "BRAKE_TAU",
    # environment
    "T_AMB", "P_AMB",
    # effects (flag + parameters)
    "WIND_ON", "WIND_MEAN", "WIND_DIR", "WIND_GUST_STD", "WIND_GUST_TAU", "WIND_DIR_STD",
    "PAYLOAD_ON", "PAYLOAD_STD", "PAYLOAD_MIN", "PAYLOAD_MAX",
    "WARM_ON", "WARM_FACTOR", "WARM_DIST",
    "WINTER_ON", "WINTER_RR", "WINTER_CS",
    "DRAG_ON", "DRAG_ROOFBOX", "DRAG_WIN", "DRAG_SUN", "DRAG_RATE",
    "BANK_ON", "BANK_SCALE", "BANK_GAIN", "BANK_MAX",
    "WET_ON", "WET_FACTOR", "WET_F1",
    "OIL_ON", "OIL_START",
    "PAD_ON", "PAD_TCOEF", "PAD_TREF", "PAD_RW_STD",
    "BARO_ON", "BARO_H", "AUX_ON", "AUX_EXTRA",
    # driver
    "DRV_ALAT", "DRV_AMAX", "DRV_BMAX", "DRV_BPLAN", "DRV_TAU", "DRV_KI", "DRV_VAR_STD", "DRV_VAR_TAU",
    "DRV_LOOKAHEAD", "DRV_PREVIEW", "DRV_DWELL_MIN", "DRV_DWELL_MAX", "DRV_MARGIN", "DRV_EG",
    "DRV_RHO", "DRV_PEDAL_TAU", "STEER_MAX",
    # run limits
    "T_END", "S_END", "ROAD_LEN", "CYCLE_MODE",
]

# ---------------------------------------------------------------------------------------------------- log columns
LOG = [
    "T", "POS", "V", "A", "FX", "RIM", "MASS", "FR", "FR0", "FR1", "FR4", "CXA", "RHO", "GRADE", "CURV",
    "PATHCURV", "BANK", "WIND_S", "WIND_A", "CSF", "CSR", "TE", "WE", "GEAR", "CLUTCH", "PBF", "PBR", "MU",
    "AY", "ACC_X_SENS", "ACC_Y_SENS", "YAW", "BETA", "DELTA", "OIL", "LOSSF", "PSRC", "ESRC", "TAMB", "PAMB",
    "ELEV", "HEAD", "WFL", "WFR", "WRL", "WRR", "VBAT", "IBAT", "SOC", "FBRAKE", "FROLL", "FAERO", "FCLIMB",
    "FCORNER", "DRAGF", "DISC_T",
]

# ---------------------------------------------------------------------------------------------------- command
CMD = ["TRACTION", "REGEN", "FRICTION", "STEER", "GEAR_REQ", "USE_DRIVER"]

# ---------------------------------------------------------------------------------------------------- road rows
ROAD = ["S", "GRADE", "CURV", "BANK", "VLIM", "HEAD", "ELEV", "VPLAN", "CRUISE"]

# ---------------------------------------------------------------------------------------------------- tables
TABLES = ["FULLLOAD", "DRAG", "FUEL", "MOTORLOSS", "DIFFLOSS", "STEER", "GBLOSS"]  # GBLOSS + (G-1) per gear

__all__: list[str] = []
for _prefix, _names in (("S_", STATE), ("P_", PARAMS), ("L_", LOG), ("C_", CMD), ("R_", ROAD), ("T_", TABLES)):
    for _i, _n in enumerate(_names):
        globals()[_prefix + _n] = _i
        __all__.append(_prefix + _n)
N_STATE = len(STATE)
N_PARAMS = len(PARAMS)
N_LOG = len(LOG)
N_CMD = len(CMD)
N_ROAD = len(ROAD)
N_TABLES = len(TABLES) - 1 + 12  # GBLOSS for up to 12 gears
__all__ += ["N_STATE", "N_PARAMS", "N_LOG", "N_CMD", "N_ROAD", "N_TABLES", "MODE_OPEN", "MODE_SLIP", "MODE_LOCKED"]

MODE_OPEN = 0
MODE_SLIP = 1
MODE_LOCKED = 2

# gear ratios i_G(G) and gearbox inertias I_G(G) follow the named parameters in P
MAX_GEARS = 12
P_RATIO0 = N_PARAMS
P_IGEAR0 = N_PARAMS + MAX_GEARS
N_P_TOTAL = N_PARAMS + 2 * MAX_GEARS
__all__ += ["MAX_GEARS", "P_RATIO0", "P_IGEAR0", "N_P_TOTAL"]
