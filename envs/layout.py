"""Index layout of the flat arrays the jitted simulator core works on.

The numba core (``physics.py``, ``driver.py``) takes a handful of flat float64 arrays instead of Python objects so
that one call costs a few microseconds: ``X`` (state), ``P`` (parameters), ``tabs`` + ``ti`` (lookup tables and
their descriptors), ``road`` (road attributes over distance), ``cmd`` (the command) and ``log`` (one row per
10-ms substep). The indices below are plain module-level integer constants (numba freezes them at compile time;
ruff and mypy resolve every name): ``S_*`` state, ``P_*`` parameters, ``L_*`` log columns, ``C_*`` command,
``R_*`` road rows, ``T_*`` tables. The name lists (``STATE``, ``PARAMS``, ...) give the same order as strings;
:func:`_check_layout` verifies at import that constants and lists agree.
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
S_T = 0
S_POS = 1
S_V = 2
S_A = 3
S_NLOG = 4
# drive-train
S_GEAR = 5
S_MODE = 6
S_OMEGA_E = 7
S_SLIP_TIMER = 8
S_LAST_SHIFT = 9
S_TE = 10
S_TC = 11
S_PBF = 12
S_PBR = 13
S_SOC = 14
# lateral
S_BETA = 15
S_YAW = 16
S_DELTA = 17
S_EY = 18
S_EPSI = 19
S_AY = 20
S_AY_MAX = 21
S_AY_WARN_N = 22
# drifting quantities
S_MASS = 23
S_DRAGF = 24
S_WIN_OPEN = 25
S_SUN_OPEN = 26
S_GUST = 27
S_WIND_DIR_DEV = 28
S_OIL_T = 29
S_DISC_T = 30
S_MU_RW = 31
S_PAYLOAD_STOP = 32
# road / driver bookkeeping
S_RIDX = 33
S_STOP_IDX = 34
S_DWELL = 35
S_DWELL_LEFT = 36
S_DRV_I = 37
S_DRV_VAR = 38
S_DRV_VAR2 = 39
S_DRV_F = 40
S_CYC_IDX = 41
# energy ledger (cumulative) [J]
S_E_SOURCE = 42
S_W_SHAFT = 43
S_D_GEARBOX = 44
S_D_DIFF = 45
S_D_CLUTCH = 46
S_D_BRAKE = 47
S_D_ROLL = 48
S_D_AERO = 49
S_D_CORNER = 50
S_W_CLIMB = 51
S_E_PAYLOAD_PE = 52

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
P_DT = 0
P_KIND_BEV = 1
P_DRIVEN = 2
P_N_GEARS = 3
# body / tires / aero
P_MASS0 = 4
P_L = 5
P_LF = 6
P_LR = 7
P_IZ = 8
P_TRACK_F = 9
P_TRACK_R = 10
P_PITCH_GRAD = 11
P_ROLL_GRAD = 12
P_RW = 13
P_IW4 = 14
P_FR0 = 15
P_FR1 = 16
P_FR4 = 17
P_CF = 18
P_CR = 19
P_CX_SLIP = 20
P_TOE = 21
P_CW = 22
P_AREA = 23
P_YAW_DRAG = 24
# drive-train
P_ID = 25
P_I_DIFF = 26
P_I_CLUTCH = 27
P_I_SOURCE = 28
P_IDLE = 29
P_MAX_SPEED = 30
P_MAX_TORQUE = 31
P_MAX_POWER = 32
P_REGEN_T = 33
P_REGEN_P = 34
P_UP_LO = 35
P_UP_HI = 36
P_DN_LO = 37
P_DN_HI = 38
P_SHIFT_MIN = 39
P_SYNC_TAU = 40
P_MAX_SLIP = 41
P_LAUNCH = 42
P_LOCK_SLIP = 43
P_OIL_WARM = 44
P_OIL_COLD_FACTOR = 45
P_OIL_TAU = 46
P_BAT_CAP = 47
P_BAT_VOC = 48
P_BAT_R = 49
P_AUX_P = 50
# brakes
P_AB_F = 51
P_AB_R = 52
P_RB_F = 53
P_RB_R = 54
P_MU0 = 55
P_BRAKE_SHARE = 56
P_P_MAX = 57
P_DISC_C = 58
P_DISC_H = 59
P_DISC_HV = 60
P_BRAKE_TAU = 61
# environment
P_T_AMB = 62
P_P_AMB = 63
# effects (flag + parameters)
P_WIND_ON = 64
P_WIND_MEAN = 65
P_WIND_DIR = 66
P_WIND_GUST_STD = 67
P_WIND_GUST_TAU = 68
P_WIND_DIR_STD = 69
P_PAYLOAD_ON = 70
P_PAYLOAD_STD = 71
P_PAYLOAD_MIN = 72
P_PAYLOAD_MAX = 73
P_WARM_ON = 74
P_WARM_FACTOR = 75
P_WARM_DIST = 76
P_WINTER_ON = 77
P_WINTER_RR = 78
P_WINTER_CS = 79
P_DRAG_ON = 80
P_DRAG_ROOFBOX = 81
P_DRAG_WIN = 82
P_DRAG_SUN = 83
P_DRAG_RATE = 84
P_BANK_ON = 85
P_BANK_SCALE = 86
P_BANK_GAIN = 87
P_BANK_MAX = 88
P_WET_ON = 89
P_WET_FACTOR = 90
P_WET_F1 = 91
P_OIL_ON = 92
P_OIL_START = 93
P_PAD_ON = 94
P_PAD_TCOEF = 95
P_PAD_TREF = 96
P_PAD_RW_STD = 97
P_BARO_ON = 98
P_BARO_H = 99
P_AUX_ON = 100
P_AUX_EXTRA = 101
# driver
P_DRV_ALAT = 102
P_DRV_AMAX = 103
P_DRV_BMAX = 104
P_DRV_BPLAN = 105
P_DRV_TAU = 106
P_DRV_KI = 107
P_DRV_VAR_STD = 108
P_DRV_VAR_TAU = 109
P_DRV_LOOKAHEAD = 110
P_DRV_PREVIEW = 111
P_DRV_DWELL_MIN = 112
P_DRV_DWELL_MAX = 113
P_DRV_MARGIN = 114
P_DRV_EG = 115
P_DRV_RHO = 116
P_DRV_PEDAL_TAU = 117
P_STEER_MAX = 118
# run limits
P_T_END = 119
P_S_END = 120
P_ROAD_LEN = 121
P_CYCLE_MODE = 122

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

# ---------------------------------------------------------------------------------------------------- command
CMD = ["TRACTION", "REGEN", "FRICTION", "STEER", "GEAR_REQ", "USE_DRIVER"]
C_TRACTION = 0
C_REGEN = 1
C_FRICTION = 2
C_STEER = 3
C_GEAR_REQ = 4
C_USE_DRIVER = 5

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

N_STATE = len(STATE)
N_PARAMS = len(PARAMS)
N_LOG = len(LOG)
N_CMD = len(CMD)
N_ROAD = len(ROAD)
N_TABLES = len(TABLES) - 1 + 12  # GBLOSS for up to 12 gears

MODE_OPEN = 0
MODE_SLIP = 1
MODE_LOCKED = 2

# gear ratios i_G(G) and gearbox inertias I_G(G) follow the named parameters in P
MAX_GEARS = 12
P_RATIO0 = N_PARAMS
P_IGEAR0 = N_PARAMS + MAX_GEARS
N_P_TOTAL = N_PARAMS + 2 * MAX_GEARS


def _check_layout() -> None:
    """Every name list entry has its constant at its position (an edit of one without the other fails here)."""
    for prefix, names in (("S_", STATE), ("P_", PARAMS), ("L_", LOG), ("C_", CMD), ("R_", ROAD), ("T_", TABLES)):
        for i, name in enumerate(names):
            if globals().get(prefix + name) != i:
                raise RuntimeError(f"layout: {prefix + name} must be {i} (position in the name list)")


_check_layout()
