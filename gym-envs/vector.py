"""``roadload/EcoDrive-v0`` as a native :class:`gymnasium.vector.VectorEnv`: N vehicles advanced in one compiled call.

``gymnasium.make_vec("roadload/EcoDrive-v0", num_envs=N, vectorization_mode="vector_entry_point")`` builds
:class:`EcoDriveVectorEnv`. Every sub-environment is the single env :class:`roadload.gym.ecodrive.EcoDriveEnv`
in batch form: the same simulator core (``roadload.envs.physics.advance``, the jitted substeps, called per vehicle
inside one compiled loop over the per-vehicle state arrays, optionally split over numba threads -- no second
physics), the same action mapping,
reward terms, observation (mode ``'state'``) and ``info`` keys. Episodes are set up exactly as the single env does
(road drawn from the sub-env's RNG, simulator built from the preset), so with the same seeds every sub-env's
trajectory equals the single env's (tests/gym/test_vector.py, to 1e-9).

Autoreset: gymnasium 1.x next-step semantics by default (the step after a terminal / truncated step resets that
sub-env, ignores its action and returns its first observation with reward 0); ``autoreset_mode='same_step'``
resets in the same step and puts the final observation / info into ``info['final_obs']`` / ``info['final_info']``
(used by the stable-baselines3 adapter, :mod:`roadload.gym.sb3`).

Seeds: ``reset(seed=s)`` seeds sub-env i with ``s + i`` (as ``SyncVectorEnv``); a list gives one seed per sub-env.

Threads: ``threads=k`` (a keyword of the constructor and of ``gymnasium.make_vec``, not an EcoDriveConfig field: it
does not change any trajectory, tests/gym/test_vector.py) splits the vehicles into k blocks, one numba thread each.
numba's OpenMP layer by default makes an idle thread spin for a while before it sleeps; on a machine whose cores are
shared, a spinning thread burns the time slice the other thread needs to reach the per-step barrier, and 2 threads
ran 3x slower than one (10-14k against 34-41k env steps/s at N = 256, load average 7-8). With
``OMP_WAIT_POLICY=PASSIVE`` the same runs gave 68-146k. So the first env with ``threads > 1`` sets
``OMP_WAIT_POLICY=PASSIVE`` unless the variable is already set (set ``OMP_WAIT_POLICY=ACTIVE`` beforehand for
dedicated cores) and unless numba's thread pool has already started; :func:`openmp_wait_policy` reports it.
libgomp reads the variable once, when it is loaded: if torch (stable-baselines3) was imported first, setting it
here has no effect (2 threads then ran 32k instead of 160k env steps/s on the loaded machine) and the env warns;
set ``OMP_WAIT_POLICY`` in the environment before Python starts in that case (scripts/bench_gym.py does).

Not batched: observation modes ``'can'`` and ``'can+estimates'`` (the CAN sensor model and the online estimator
are per-vehicle Python objects) and time-varying (scheduled) effects; use ``vectorization_mode='sync'`` for those.
"""

from __future__ import annotations

import os
import warnings
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from gymnasium.utils import seeding
import numba
from numba import prange

from roadload.envs import physics
from roadload.envs._jit import dependent_jit
from roadload.envs.layout import (C_GEAR_REQ, C_STEER, C_TRACTION, C_USE_DRIVER, N_CMD, N_LOG, N_PARAMS, N_ROAD,
                                  N_STATE, S_A, S_AY, S_E_SOURCE, S_GEAR, S_NLOG, S_POS, S_T, S_V)
from roadload.envs.simulator import Simulator
from roadload.gym.actions import BOUND_TOLERANCE, validate_actions
from roadload.gym.config import SPACE_FIELDS_ECODRIVE, EcoDriveConfig, GymConfigError, make_config, updated_config
from roadload.gym.ecodrive import (PREVIEW_GRID, STOP_HORIZON, DriveScales, RouteTable, _look_ahead, cut_profile,
                                   observation_layout, shield_command)
from roadload.gym import ecodrive as _ecodrive
from roadload.presets import get_preset
from roadload.road_profiles import RoadProfile, load_profile_start

kernel = dependent_jit(__file__, _ecodrive.__file__)
"""The decorator of this module's compiled kernels: their cache is keyed by the core's sources, this module's and
ecodrive.py's (whose compiled look-ahead and shield they call)."""

COST_NAMES = ("energy", "time", "speeding", "lateral", "stop", "jerk", "progress")
"""Reward terms, in the order of ``info['terms']`` / ``info['costs']`` (EcoDriveEnv)."""
INFO_SCALARS = ("t", "s", "v", "a", "gear", "speed_limit", "source_energy_total", "road_seed", "route_length",
                "schedule_time")

# rows of the float info block one step returns (filled by the compiled step; each info array is a row view of a
# block allocated afresh per step, so infos a user keeps are never overwritten): INFO_SCALARS without the two
# integer keys, then return_costs, terms and costs (7 each, COST_NAMES order)
I_T, I_S, I_V, I_A, I_LIMIT, I_ENERGY_TOTAL, I_ROUTE_LENGTH, I_SCHEDULE = range(8)
I_RETURN, I_TERMS, I_COSTS = 8, 15, 22
N_INFO = 29
_INFO_ROWS = (("t", I_T), ("s", I_S), ("v", I_V), ("a", I_A), ("gear", -1), ("speed_limit", I_LIMIT),
              ("source_energy_total", I_ENERGY_TOTAL), ("road_seed", -2), ("route_length", I_ROUTE_LENGTH),
              ("schedule_time", I_SCHEDULE))

# per-env scalars of the episode bookkeeping (columns of the `E` array)
E_LIMIT, E_U_PREV, E_A_PREV, E_LAST_ENERGY, E_TIME_LIMIT, E_LENGTH, E_ROUTE_TIME = range(7)
N_E = 7
NO_SHIELD = 1.0e9
"""Envelope value [m/s] of a sub-env without the speed shield (the cap never binds)."""
_SCHEDULE = RouteTable.SCHEDULE
_SPEED_LIMIT = RouteTable.SPEED_LIMIT


# --------------------------------------------------------------------------------------------- compiled kernels
@kernel()
def _observe_from_look_ahead(X, E, la, stops, n_stops, scale, low, high, buf, out):
    """The single env's 'state' observation (EcoDriveEnv._observe) for one vehicle -> out (float32), from the
    route table's look-ahead la (rows at s + preview, read by _look_ahead)."""
    s = X[S_POS]
    buf[0] = X[S_V]
    buf[1] = X[S_A]
    k = 2
    m = la.shape[1]
    for r in range(3):
        for j in range(m):
            buf[k + r * m + j] = la[r, j]
    k += 3 * m
    buf[k] = X[S_T] - la[_SCHEDULE, 0]
    buf[k + 1] = max(E[E_LENGTH] - s, 0.0)
    nxt = STOP_HORIZON
    for j in range(n_stops):  # bisect_left: first stop >= s
        if stops[j] >= s:
            nxt = min(stops[j] - s, STOP_HORIZON)
            break
    buf[k + 2] = nxt
    buf[k + 3] = E[E_U_PREV]
    for j in range(buf.size):
        o = buf[j] / scale[j]
        if o < low[j]:
            o = low[j]
        elif o > high[j]:
            o = high[j]
        out[j] = np.float32(o)


@kernel(inline="always")
def _set_command(c, ui, v, F):
    """The simulator command of a normalised action ui in [-1, 1] at speed v [m/s]: wheel force ui x the peak
    traction force (capped by peak power / v) or ui x the full brake force [N]
    (DriveScales ``F = (peak traction force, peak power, full brake force)``), built-in steering and gears."""
    c[C_USE_DRIVER] = 2.0
    c[C_TRACTION] = ui * min(F[0], F[1] / max(v, 1.0)) if ui >= 0.0 else ui * F[2]
    c[C_STEER] = np.nan
    c[C_GEAR_REQ] = -1.0


@kernel()
def advance_range(lo, hi, active, u, X, P, tabs, ti, road, road_n, stops, stops_n, cycle, rng, cmd, log, n_sub, F):
    """The bare batched physics for vehicles lo..hi-1: for every active vehicle i, the wheel force of command u[i]
    (DriveScales ``F = (peak traction force, peak power, full brake force)``) held for n_sub substeps of the
    simulator core."""
    for i in range(lo, hi):
        if not active[i]:
            continue
        c = cmd[i]
        _set_command(c, u[i], X[i, S_V], F)
        X[i, S_NLOG] = 0.0  # the env reads the state, not the log (which has no rows: nothing is logged)
        physics.advance(X[i], P[i], tabs, ti, road[i, :, :road_n[i]], stops[i, :stops_n[i]], cycle, rng[i], c,
                        log[i], n_sub)


@kernel(inline="always")
def _gather_info(i, x, e, ret_costs, tm, cs, with_terms, info, ints, road_seed):
    """Stage 'info' of vehicle i: the single env's info values (EcoDriveEnv._info; terms / costs only for a vehicle
    that stepped, zeros otherwise) -> column i of the info block (float rows I_*) and of the integer block (gear,
    road seed)."""
    info[I_T, i] = x[S_T]
    info[I_S, i] = x[S_POS]
    info[I_V, i] = x[S_V]
    info[I_A, i] = x[S_A]
    info[I_LIMIT, i] = e[E_LIMIT]
    info[I_ENERGY_TOTAL, i] = x[S_E_SOURCE]
    info[I_ROUTE_LENGTH, i] = e[E_LENGTH]
    info[I_SCHEDULE, i] = e[E_ROUTE_TIME]
    ints[0, i] = np.int64(x[S_GEAR])  # truncation, as ndarray.astype(np.int64)
    ints[1, i] = road_seed[i]
    for k in range(7):
        info[I_RETURN + k, i] = ret_costs[i, k]
        info[I_TERMS + k, i] = tm[k] if with_terms else 0.0
        info[I_COSTS + k, i] = cs[k] if with_terms else 0.0


@kernel()
def _step_range(lo, hi, active, u, X, P, tabs, ti, road, road_n, stops, stops_n, cycle, rng, cmd, log, n_sub, F,
                E, table, table_n, envelope, preview, rstops, rstops_n, W, dt, lat_lim, stop_speed,
                scale, low, high, obs, reward, terms, costs, ret_costs, term, trunc, buf, la,
                info, ints, road_seed):
    """One env step (EcoDriveEnv.step) of vehicles lo..hi-1 as named stages per vehicle: action (clip to [-1, 1],
    speed shield), physics (the simulator core), speed limit, reward terms, done flags, 'state' observation and
    info. A vehicle that is not active (reset in this step, next-step autoreset) only gets reward 0, no done flags,
    no terms and its info. W = (energy, time, speeding, lateral, stop, jerk, progress, scale) reward weights;
    reward / term / trunc / info / ints are written for every vehicle."""
    for i in range(lo, hi):
        x = X[i]
        e = E[i]
        tm = terms[i]
        cs = costs[i]
        if not active[i]:
            reward[i] = 0.0
            term[i] = False
            trunc[i] = False
            _gather_info(i, x, e, ret_costs, tm, cs, False, info, ints, road_seed)
            continue
        # stage 'action': u clipped to [-1, 1], then capped by the speed shield
        # u <= SHIELD_GAIN (v_env(s) - v) (no-op without the shield: envelope = NO_SHIELD)
        ui = u[i]
        ui = -1.0 if ui < -1.0 else (1.0 if ui > 1.0 else ui)
        s0 = x[S_POS]
        v0 = x[S_V]
        ui = shield_command(envelope[i], table_n[i], s0, v0, ui)
        limit0 = e[E_LIMIT]
        # stage 'physics': wheel force F_w = u min(F_peak, P_max / max(v, 1)) (u >= 0) or u F_brake (u < 0),
        # held for n_sub substeps of the simulator core
        c = cmd[i]
        _set_command(c, ui, v0, F)
        x[S_NLOG] = 0.0
        physics.advance(x, P[i], tabs, ti, road[i, :, :road_n[i]], stops[i, :stops_n[i]], cycle, rng[i], c,
                        log[i], n_sub)
        # stage 'look-ahead': the route table (grade, curvature, speed limit, schedule time; linear interpolation)
        # at s1 + preview; preview[0] = 0, so column 0 holds the speed limit at s1 itself (the same arithmetic as
        # RouteTable.at), read once for the reward and the observation
        tab = table[i, :, :table_n[i]]
        s1 = x[S_POS]
        v1 = x[S_V]
        lai = la[i]
        _look_ahead(tab, PREVIEW_GRID, preview, s1, lai)
        limit = lai[_SPEED_LIMIT, 0]
        e[E_LIMIT] = limit
        length = e[E_LENGTH]
        # stage 'reward terms' (EcoDriveReward): speeding = (mean(v) - mean(v_lim))+ dt, lateral = (|a_y| - a_max)+ dt,
        # stop = stop lines s0 < s_stop <= s1 crossed faster than stop_speed (speed interpolated linearly),
        # jerk^2 dt with jerk = (a1 - a0) / dt, progress = min(s1, L) - min(s0, L), energy = E_source(t1) - E_source(t0)
        speeding = max(0.0, 0.5 * (v0 + v1 - limit0 - limit)) * dt
        lateral = max(0.0, abs(x[S_AY]) - lat_lim) * dt
        stop = 0.0
        for j in range(rstops_n[i]):
            st = rstops[i, j]
            if st > s0 and st <= s1:
                frac = (st - s0) / max(s1 - s0, 1e-9)
                if v0 + frac * (v1 - v0) > stop_speed:
                    stop += 1.0
        jerk = (x[S_A] - e[E_A_PREV]) / dt
        # stage 'done flags': terminated at the route end, truncated at the time limit
        terminated = s1 >= length - 1e-6
        truncated = (not terminated) and x[S_T] >= e[E_TIME_LIMIT] - 1e-9
        progress = min(s1, length) - min(s0, length)
        energy = x[S_E_SOURCE] - e[E_LAST_ENERGY]
        e[E_LAST_ENERGY] = x[S_E_SOURCE]
        tm[0] = energy
        tm[1] = dt
        tm[2] = speeding
        tm[3] = lateral
        tm[4] = stop
        tm[5] = jerk * jerk * dt
        tm[6] = progress
        # stage 'reward': r = -scale * sum_k cost_k with cost_k = w_k term_k (progress: -w_progress ds)
        total = 0.0
        for k in range(7):
            cs[k] = (-W[6] * tm[6]) if k == 6 else W[k] * tm[k]
            total += cs[k]
            ret_costs[i, k] += cs[k]
        reward[i] = -W[7] * total
        term[i] = terminated
        trunc[i] = truncated
        e[E_U_PREV] = ui
        e[E_A_PREV] = x[S_A]
        # stage 'observation' (EcoDriveEnv._observe, mode 'state') and stage 'info'
        _observe_from_look_ahead(x, e, lai, rstops[i], rstops_n[i], scale, low, high, buf[i], obs[i])
        _gather_info(i, x, e, ret_costs, tm, cs, True, info, ints, road_seed)


@kernel(parallel=True)
def _step_threads(n_chunks, active, u, X, P, tabs, ti, road, road_n, stops, stops_n, cycle, rng, cmd, log, n_sub,
                  F, E, table, table_n, envelope, preview, rstops, rstops_n, W, dt, lat_lim, stop_speed, scale, low,
                  high, obs, reward, terms, costs, ret_costs, term, trunc, buf, la, info, ints,
                  road_seed):
    """_step_range over n_chunks contiguous blocks of vehicles, one numba thread each."""
    n = X.shape[0]
    for c in prange(n_chunks):
        _step_range(c * n // n_chunks, (c + 1) * n // n_chunks, active, u, X, P, tabs, ti, road, road_n, stops,
                    stops_n, cycle, rng, cmd, log, n_sub, F, E, table, table_n, envelope, preview, rstops, rstops_n,
                    W, dt, lat_lim, stop_speed, scale, low, high, obs, reward, terms, costs, ret_costs, term, trunc,
                    buf, la, info, ints, road_seed)


@kernel()
def _gather_info_all(X, E, ret_costs, terms, costs, info, ints, road_seed):
    """Stage 'info' of every vehicle without terms (the info of reset())."""
    for i in range(X.shape[0]):
        _gather_info(i, X[i], E[i], ret_costs, terms[i], costs[i], False, info, ints, road_seed)


@kernel()
def _actions_in_bounds(u, tol):
    """True when every action is finite and inside [-1 - tol, 1 + tol] (the fast path of the action check)."""
    for j in range(u.size):
        if not (u[j] >= -1.0 - tol and u[j] <= 1.0 + tol):  # NaN fails too
            return False
    return True


@kernel(parallel=True)
def _advance_threads(n_chunks, active, u, X, P, tabs, ti, road, road_n, stops, stops_n, cycle, rng, cmd, log,
                     n_sub, F):
    n = X.shape[0]
    for c in prange(n_chunks):
        advance_range(c * n // n_chunks, (c + 1) * n // n_chunks, active, u, X, P, tabs, ti, road, road_n, stops,
                      stops_n, cycle, rng, cmd, log, n_sub, F)


_WAIT_POLICY_LATE = False
"""True when this module set OMP_WAIT_POLICY after an OpenMP runtime was already loaded (then not in effect)."""


def _openmp_runtime_loaded() -> bool:
    """Whether an OpenMP runtime (libgomp / libiomp / libomp) is mapped into this process (Linux; False elsewhere).
    libgomp reads OMP_WAIT_POLICY once, when it is loaded: torch (imported by stable-baselines3) loads it."""
    try:
        with open("/proc/self/maps") as f:
            maps = f.read()
    except OSError:
        return False
    return any(name in maps for name in ("libgomp", "libiomp", "libomp"))


def _prefer_passive_openmp_wait() -> None:
    """OMP_WAIT_POLICY=PASSIVE unless set, before numba's OpenMP pool starts (module docstring: Threads); a
    RuntimeWarning when an OpenMP runtime is already loaded, so that the setting cannot take effect any more (with
    torch imported first, 2 threads ran 32k instead of 160k env steps/s at N = 256 on the loaded 2-core machine)."""
    global _WAIT_POLICY_LATE
    if "OMP_WAIT_POLICY" in os.environ:
        return
    try:
        numba.threading_layer()  # raises ValueError while no parallel function has run: the pool is not started
        return
    except ValueError:
        pass
    if _openmp_runtime_loaded():
        _WAIT_POLICY_LATE = True
        warnings.warn("threads > 1: an OpenMP runtime is already loaded in this process (e.g. by torch), so "
                      "OMP_WAIT_POLICY=PASSIVE can no longer take effect and idle OpenMP threads spin, which is "
                      "several times slower on a machine whose cores are busy; set OMP_WAIT_POLICY=PASSIVE in the "
                      "environment before Python starts (or before importing torch / stable-baselines3)",
                      RuntimeWarning, stacklevel=3)
    os.environ["OMP_WAIT_POLICY"] = "PASSIVE"


def openmp_wait_policy() -> str:
    """The ``OMP_WAIT_POLICY`` of this process ('default' = unset: libgomp spins, then sleeps; a note when this
    module set it after the OpenMP runtime was loaded, i.e. without effect)."""
    policy = os.environ.get("OMP_WAIT_POLICY", "default")
    return f"{policy} (set after the OpenMP runtime was loaded: not in effect)" if _WAIT_POLICY_LATE else policy


# --------------------------------------------------------------------------------------------- the vector env
class EcoDriveVectorEnv(gym.vector.VectorEnv):
    """N EcoDrive-v0 sub-environments stepped in one compiled call (module docstring).

    ``config`` / keyword overrides as for the single env (every sub-env shares them); ``autoreset_mode`` is
    ``'next_step'`` (gymnasium's default) or ``'same_step'``; ``threads``: numba threads that split the vehicles
    (default 1; 2 uses both cores of an idle 2-core machine, see the module docstring on the OpenMP wait policy)."""

    metadata = {"render_modes": [], "autoreset_mode": gym.vector.AutoresetMode.NEXT_STEP}

    def __init__(self, num_envs: int = 1, config: EcoDriveConfig | dict | None = None,
                 autoreset_mode: str | gym.vector.AutoresetMode = "next_step", threads: int = 1,
                 **overrides: Any) -> None:
        if isinstance(num_envs, bool) or not isinstance(num_envs, (int, np.integer)) or num_envs < 1:
            raise GymConfigError(f"num_envs: expected an integer >= 1, got {num_envs!r}")
        modes = {"next_step": gym.vector.AutoresetMode.NEXT_STEP, "same_step": gym.vector.AutoresetMode.SAME_STEP}
        mode = modes.get(str(autoreset_mode).lower(), autoreset_mode if autoreset_mode in modes.values() else None)
        if mode is None:
            raise GymConfigError(f"autoreset_mode: expected 'next_step' or 'same_step' (or the AutoresetMode), got "
                                 f"{autoreset_mode!r}")
        self.autoreset_mode = mode
        if isinstance(threads, bool) or not isinstance(threads, (int, np.integer)) or threads < 1:
            raise GymConfigError(f"threads: expected an integer >= 1, got {threads!r}")
        self.threads = int(threads)
        if self.threads > 1:
            _prefer_passive_openmp_wait()
        self.metadata = {**self.metadata, "autoreset_mode": mode}
        self.config: EcoDriveConfig = make_config(EcoDriveConfig, config, **overrides)
        self._check_batchable(self.config)
        self.num_envs = int(num_envs)
        n = self.num_envs
        cfg = self.config
        self.layout = observation_layout(cfg)
        n_obs = len(self.layout)
        self._scale = np.array([1.0 if cfg.obs_scaling == "si" else row[2] for row in self.layout])
        self._low = np.array([row[3] for row in self.layout]) / self._scale
        self._high = np.array([row[4] for row in self.layout]) / self._scale
        self.single_observation_space = spaces.Box(self._low.astype(np.float32), self._high.astype(np.float32),
                                                   shape=(n_obs,), dtype=np.float32)
        self._action_box = spaces.Box(-1.0, 1.0, shape=(1,), dtype=np.float32)
        self.single_action_space = self._action_box
        self.observation_space = gym.vector.utils.batch_space(self.single_observation_space, n)
        self.action_space = gym.vector.utils.batch_space(self.single_action_space, n)
        self._preview = np.array((0.0, *cfg.preview_distances))  # column 0 = at s: the compiled step's limit
        # per-vehicle arrays (grown on demand where roads differ in length)
        self._X = np.zeros((n, N_STATE))
        self._P = np.zeros((n, N_PARAMS))
        self._road = np.zeros((n, N_ROAD, 2))
        self._road_n = np.zeros(n, dtype=np.int64)
        self._stops = np.zeros((n, 1))
        self._stops_n = np.zeros(n, dtype=np.int64)
        self._rng = np.zeros((n, 1), dtype=np.uint64)
        self._cmd = np.zeros((n, N_CMD))
        self._n_sub = cfg.n_substeps
        # a truth log of no rows: the env reads the state, never the log, and the core skips writing a row when the
        # log is full (physics.substep), which saves ~10% of a step; the state is the same with or without it
        self._log = np.zeros((n, N_LOG, 0))
        self._E = np.zeros((n, N_E))
        self._table = np.zeros((n, 4, 2))
        self._table_n = np.zeros(n, dtype=np.int64)
        self._envelope = np.full((n, 2), NO_SHIELD)
        self._rstops = np.zeros((n, 1))
        self._rstops_n = np.zeros(n, dtype=np.int64)
        self._obs = np.zeros((n, n_obs), dtype=np.float32)
        self._reward = np.zeros(n)
        self._terms = np.zeros((n, 7))
        self._costs = np.zeros((n, 7))
        self._ret_costs = np.zeros((n, 7))
        self._term = np.zeros(n, dtype=bool)
        self._trunc = np.zeros(n, dtype=bool)
        self._buf = np.zeros((n, n_obs))
        self._la = np.zeros((n, 4, self._preview.size))
        self._road_seed = np.zeros(n, dtype=np.int64)
        self._gear = np.zeros(n, dtype=np.int64)
        self._sims: list[Simulator | None] = [None] * n
        self._templates: dict[str, Simulator] = {}  # per repr(effects): the simulator new roads are set up from
        self._keys: list[tuple | None] = [None] * n
        self._routes: list[RouteTable | None] = [None] * n
        self._rngs: list[np.random.Generator] = [seeding.np_random()[0] for _ in range(n)]
        self._needs_reset = np.ones(n, dtype=bool)  # step() before reset() resets
        self._spec = get_preset(cfg.vehicle)
        self._drive = DriveScales.from_spec(self._spec)
        self._F = np.array([self._drive.peak_traction_force, self._drive.peak_power, self._drive.full_brake_force])
        self._cycle = np.zeros((2, 2))
        self._cycle[0, 1] = 1.0
        self._tabs: np.ndarray | None = None  # vehicle tables, shared by all sub-envs (set by the first setup)
        self._ti: np.ndarray | None = None
        self._configs: list[EcoDriveConfig] = [cfg] * n
        w = cfg.reward
        self._W = np.array([w.energy, w.time, w.speeding, w.lateral, w.stop, w.jerk, w.progress, w.scale])
        self._all_active = np.ones(n, dtype=bool)
        self._args: tuple | None = None  # the compiled step's arguments (_step_args)
        self._args_tail: tuple = ()
        self._args_work: tuple = ()
        self._setup_one(0, cfg, cfg.road_seed if cfg.road_seed is not None else cfg.road_seed_range[0], 0)

    # ------------------------------------------------------------------ checks
    @staticmethod
    def _check_batchable(cfg: EcoDriveConfig) -> None:
        if cfg.observation != "state":
            raise GymConfigError(f"observation: the native vector env batches mode 'state' only, got "
                                 f"{cfg.observation!r}; use gymnasium.make_vec(..., vectorization_mode='sync') for "
                                 f"'can' / 'can+estimates'")

    # the fields the compiled step reads once for the whole batch (reward weights W, dt, the lateral limit of the
    # reward, the stop speed, the observation scale and preview): a reset option changing one of them for some
    # sub-envs would be silently ignored, so it is refused
    SHARED_FIELDS = ("reward", "control_period", "preview_distances", "lateral_acceleration_limit", "stop_speed",
                     "obs_scaling", "estimator")

    def _check_per_env(self, cfg: EcoDriveConfig) -> None:
        changed = [f for f in self.SHARED_FIELDS if getattr(cfg, f) != getattr(self.config, f)]
        if changed:
            raise GymConfigError(f"reset options {changed}: the native vector env applies these to all sub-envs at "
                                 f"construction (make_vec(..., {changed[0]}=...)); per sub-env it takes road, "
                                 f"road_seed, road_seed_range, route_length, effects, initial_speed, "
                                 f"schedule_speed_fraction, time_limit and the speed-shield settings")

    # ------------------------------------------------------------------ per-env episode setup (EcoDriveEnv._setup)
    def _fit(self, name: str, width: int) -> np.ndarray:
        arr = getattr(self, name)
        if arr.shape[-1] < width:
            new = np.zeros(arr.shape[:-1] + (width,), dtype=arr.dtype)
            new[..., :arr.shape[-1]] = arr
            setattr(self, name, new)
            self._args = None  # the compiled step's argument tuple holds the old array
            arr = new
        return arr

    def _setup_one(self, i: int, cfg: EcoDriveConfig, road_seed: int, sim_seed: int) -> None:
        key = (cfg.road, road_seed, cfg.route_length, repr(cfg.effects), cfg.preview_distances,
               cfg.schedule_speed_fraction, cfg.lateral_acceleration_limit)
        if key != self._keys[i]:
            try:
                loaded = load_profile_start(cfg.road, cfg.route_length, seed=road_seed)
                if not isinstance(loaded, RoadProfile):
                    raise GymConfigError(f"road: {cfg.road!r} is not a road profile")
                profile = cut_profile(loaded, cfg.route_length)
                template = self._templates.get(key[3])
                if template is None:  # the first episode with these effects: validate and pack the vehicle
                    sim = Simulator(self._spec, profile, cfg.effects, None, sim_seed,
                                    initial_speed=cfg.initial_speed, log_capacity=self._n_sub)
                    self._templates[key[3]] = sim
                else:  # the packed vehicle and effects of that first simulator on the new road (bit for bit)
                    sim = template.on_road(profile, sim_seed, cfg.initial_speed)
                fresh = True
            except GymConfigError:
                raise
            except ValueError as exc:
                raise GymConfigError(f"cannot build the episode: {exc}") from exc
            if sim._schedules.active:
                raise GymConfigError("effects: time-varying (scheduled) effects are not batched by the native "
                                     "vector env; use vectorization_mode='sync'")
            route = RouteTable(profile, self._preview, cfg.schedule_speed_fraction, cfg.lateral_acceleration_limit)
            self._sims[i], self._routes[i], self._keys[i] = sim, route, key
            self._road_seed[i] = road_seed
            if self._tabs is None:
                self._tabs, self._ti = sim.tabs, sim.ti
            nr = sim._road.shape[1]
            self._fit("_road", nr)[i, :, :nr] = sim._road
            self._road_n[i] = nr
            nt = route.table.shape[1]
            self._fit("_table", nt)[i, :, :nt] = route.table
            self._table_n[i] = nt
            rs = np.asarray(route.stops, dtype=float)
            self._fit("_rstops", max(rs.size, 1))[i, :rs.size] = rs
            self._rstops_n[i] = rs.size
        else:
            fresh = False
        cached_sim, cached_route = self._sims[i], self._routes[i]
        if cached_sim is None or cached_route is None:
            raise GymConfigError(f"sub-env {i}: no episode set up (its first setup failed)")
        sim, route = cached_sim, cached_route
        if not fresh:  # a new simulator is already reset with these seeds (as EcoDriveEnv's second reset leaves it)
            sim.reset(seed=sim_seed, initial_speed=cfg.initial_speed)
        ns = sim._stops.size
        self._fit("_stops", max(ns, 1))[i, :ns] = sim._stops
        self._stops_n[i] = ns
        self._road[i, :, :self._road_n[i]] = sim._road  # reset may re-plan (poor_excitation)
        self._X[i] = sim.X
        self._fit("_P", sim.P.size)[i] = sim.P  # driver / effect parameters follow the N_PARAMS core block
        self._rng[i] = sim._rng
        self._cmd[i] = sim._cmd
        nt = self._table_n[i]
        self._fit("_envelope", nt)[i] = NO_SHIELD
        if cfg.speed_shield:
            self._envelope[i, :nt] = route.braking_envelope(cfg.shield_margin, cfg.shield_deceleration)
        e = self._E[i]
        e[:] = 0.0
        e[E_TIME_LIMIT] = cfg.time_limit if cfg.time_limit is not None else 2.0 * route.route_time + 30.0
        e[E_LENGTH] = route.length
        e[E_ROUTE_TIME] = route.route_time
        # the look-ahead at the start position: column 0 (preview 0 m) is the speed limit, as in the compiled step
        la = self._la[i]
        _look_ahead(self._table[i, :, :self._table_n[i]], PREVIEW_GRID, self._preview, self._X[i, S_POS], la)
        e[E_LIMIT] = la[_SPEED_LIMIT, 0]
        self._ret_costs[i] = 0.0
        _observe_from_look_ahead(self._X[i], e, la, self._rstops[i], self._rstops_n[i], self._scale, self._low,
                                 self._high, self._buf[i], self._obs[i])

    def _reset_one(self, i: int, seed: int | None, options: dict[str, Any] | None) -> None:
        if seed is not None:
            self._rngs[i], _ = seeding.np_random(seed)
        cfg = updated_config(self._configs[i], options, SPACE_FIELDS_ECODRIVE)
        if cfg.vehicle != self.config.vehicle:
            raise GymConfigError(f"options.vehicle: the native vector env runs one vehicle ({self.config.vehicle!r})"
                                 f" for all sub-envs, got {cfg.vehicle!r}")
        self._check_batchable(cfg)
        self._check_per_env(cfg)
        g = self._rngs[i]
        road_seed = cfg.road_seed if cfg.road_seed is not None else int(g.integers(*cfg.road_seed_range))
        sim_seed = int(g.integers(0, 2 ** 31 - 1))
        self._configs[i] = cfg
        self._setup_one(i, cfg, road_seed, sim_seed)

    # ------------------------------------------------------------------ gymnasium API
    def reset(self, *, seed: int | list[int | None] | None = None, options: dict[str, Any] | None = None):
        """Reset every sub-env (``options['reset_mask']``: only those where the mask is True)."""
        n = self.num_envs
        if seed is None:
            seeds: list[int | None] = [None] * n
        elif isinstance(seed, bool):
            raise ValueError(f"seed: expected an int or a list of {n} seeds, got {seed!r}")
        elif isinstance(seed, (int, np.integer)):
            seeds = [int(seed) + i for i in range(n)]
        else:
            seeds = list(seed)
            if len(seeds) != n:
                raise ValueError(f"seed: expected an int or a list of {n} seeds, got {len(seeds)}")
        opts = dict(options or {})
        mask = opts.pop("reset_mask", None)
        mask = np.ones(n, dtype=bool) if mask is None else np.asarray(mask, dtype=bool)
        if mask.shape != (n,):
            raise ValueError(f"options['reset_mask']: expected a boolean array of shape ({n},), got {mask.shape}")
        for i in np.flatnonzero(mask):
            self._reset_one(int(i), seeds[i], opts or None)
        self._needs_reset[mask] = False
        return self._obs.copy(), self._info(mask, with_terms=False)

    def _actions(self, actions: Any) -> np.ndarray:
        """The commands as float64 (n,), equal to validate_actions' float32 result: a float32 / float64 (n, 1)
        array inside the bounds takes a compiled check; anything else (and every bad action, for its error
        message) goes through validate_actions. Values within BOUND_TOLERANCE outside [-1, 1] are clipped by the
        compiled step as validate_actions clips them."""
        n = self.num_envs
        if type(actions) is np.ndarray and actions.shape == (n, 1) and actions.dtype in (np.float32, np.float64):
            flat = actions.reshape(n)
            if _actions_in_bounds(flat, BOUND_TOLERANCE):
                if flat.dtype == np.float64:  # the action space is float32: round as validate_actions does
                    flat = flat.astype(np.float32)
                return flat.astype(np.float64)
        return validate_actions(actions, self._action_box, n)[:, 0].astype(np.float64)

    def step(self, actions):
        u = self._actions(actions)
        n = self.num_envs
        reset_now = self._needs_reset
        if reset_now.any():
            active = ~reset_now
            for i in np.flatnonzero(reset_now):
                self._reset_one(int(i), None, None)
            self._needs_reset = np.zeros(n, dtype=bool)
        else:
            active = self._all_active
        reward = np.empty(n)
        term = np.empty(n, dtype=bool)
        trunc = np.empty(n, dtype=bool)
        info_block = np.empty((N_INFO, n))
        ints = np.empty((2, n), dtype=np.int64)
        self._step_compiled(active, u, reward, term, trunc, info_block, ints)
        info = self._info_dict(info_block, ints, np.ones(n, dtype=bool), active)
        if self.autoreset_mode == gym.vector.AutoresetMode.NEXT_STEP:
            self._needs_reset = term | trunc
            return self._obs.copy(), reward, term, trunc, info
        # same step: reset the finished sub-envs now, report their last observation / info
        done = term | trunc
        obs = self._obs.copy()
        if done.any():
            final_obs = np.where(done[:, None], obs, 0.0).astype(np.float32)
            for i in np.flatnonzero(done):
                self._reset_one(int(i), None, None)
            obs = self._obs.copy()
            fresh = self._info(done, with_terms=False)
            info = {**fresh, "final_obs": final_obs, "_final_obs": done, "final_info": info, "_final_info": done}
        return obs, reward, term, trunc, info

    def _step_args(self) -> tuple:
        """The per-vehicle arrays and constants of the compiled step (rebuilt when a buffer grows, see _fit)."""
        if self._args is None:
            cfg = self.config
            self._args = (self._X, self._P, self._tabs, self._ti, self._road, self._road_n, self._stops,
                          self._stops_n, self._cycle, self._rng, self._cmd, self._log, self._n_sub, self._F, self._E,
                          self._table, self._table_n, self._envelope, self._preview, self._rstops, self._rstops_n,
                          self._W, cfg.control_period, cfg.lateral_acceleration_limit, cfg.stop_speed, self._scale,
                          self._low, self._high, self._obs)
            self._args_tail = (self._terms, self._costs, self._ret_costs)
            self._args_work = (self._buf, self._la)
        return self._args

    def _step_compiled(self, active: np.ndarray, u: np.ndarray, reward: np.ndarray, term: np.ndarray,
                       trunc: np.ndarray, info: np.ndarray, ints: np.ndarray) -> None:
        args = self._step_args()
        call = (active, u, *args, reward, *self._args_tail, term, trunc, *self._args_work, info, ints,
                self._road_seed)
        if self.threads > 1:
            _step_threads(self.threads, *call)
        else:
            _step_range(0, self.num_envs, *call)

    def _info_dict(self, block: np.ndarray, ints: np.ndarray, mask: np.ndarray,
                   with_terms: np.ndarray | None) -> dict[str, Any]:
        """gymnasium vector info from the info block: one array per key of the single env's info (row views of
        the block, fresh every step), '_key' = which sub-envs have it; 'terms' / 'costs' when any sub-env
        stepped (with_terms: those that did)."""
        info: dict[str, Any] = {k: (block[r] if r >= 0 else ints[-1 - r]) for k, r in _INFO_ROWS}
        rc: dict[str, Any] = {k: block[I_RETURN + j] for j, k in enumerate(COST_NAMES)}
        info["return_costs"] = rc
        for k in INFO_SCALARS:
            info["_" + k] = mask
        for k in COST_NAMES:
            rc["_" + k] = mask
        info["_return_costs"] = mask
        if with_terms is not None and with_terms.any():
            tmask = with_terms & mask
            for name, row in (("terms", I_TERMS), ("costs", I_COSTS)):
                d: dict[str, Any] = {k: block[row + j] for j, k in enumerate(COST_NAMES)}
                for k in COST_NAMES:
                    d["_" + k] = tmask
                info[name] = d
                info["_" + name] = tmask
        return info

    def _info(self, mask: np.ndarray, with_terms: bool = False) -> dict[str, Any]:
        """The info of reset() (no terms): every sub-env's current values, '_key' = mask."""
        if with_terms:
            raise ValueError("with_terms: the info with terms is built by the compiled step")
        n = self.num_envs
        block = np.empty((N_INFO, n))
        ints = np.empty((2, n), dtype=np.int64)
        _gather_info_all(self._X, self._E, self._ret_costs, self._terms, self._costs, block, ints, self._road_seed)
        return self._info_dict(block, ints, mask, None)

    # ------------------------------------------------------------------ benchmark hook
    def bare_physics_step(self, actions: np.ndarray) -> None:
        """Only the batched physics of one env step (no reward, observation, info, autoreset): the reference the
        benchmark compares the env step with."""
        u = np.asarray(actions, dtype=np.float64).reshape(self.num_envs)
        active = np.ones(self.num_envs, dtype=bool)
        args = (active, u, self._X, self._P, self._tabs, self._ti, self._road, self._road_n, self._stops,
                self._stops_n, self._cycle, self._rng, self._cmd, self._log, self._n_sub, self._F)
        if self.threads > 1:
            _advance_threads(self.threads, *args)
        else:
            advance_range(0, self.num_envs, *args)

    @property
    def sub_simulators(self) -> list[Simulator | None]:
        """The simulator objects the episodes were set up from (their state is NOT advanced by step())."""
        return list(self._sims)


def make_vector_env(num_envs: int = 1, **kwargs: Any) -> EcoDriveVectorEnv:
    """The ``vector_entry_point`` of roadload/EcoDrive-v0 (``gymnasium.make_vec`` passes num_envs + env kwargs)."""
    kwargs.pop("max_episode_steps", None)
    if "render_mode" in kwargs and kwargs["render_mode"] is not None:
        raise GymConfigError("render_mode: the native vector env does not render; use vectorization_mode='sync'")
    kwargs.pop("render_mode", None)
    return EcoDriveVectorEnv(num_envs=num_envs, **kwargs)


__all__ = ["EcoDriveVectorEnv", "make_vector_env", "advance_range", "COST_NAMES", "openmp_wait_policy"]
