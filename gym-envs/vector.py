"""``roadload/EcoDrive-v0`` as a native :class:`gymnasium.vector.VectorEnv`: N vehicles advanced in one compiled call.

``gymnasium.make_vec("roadload/EcoDrive-v0", num_envs=N, vectorization_mode="vector_entry_point")`` builds
:class:`EcoDriveVectorEnv`. Every sub-environment is the single env :class:`roadload.gym.ecodrive.EcoDriveEnv`
in batch form: both are :class:`roadload.gym.ecodrive.EcoBatch` (the single env with one sub-env) and run the one
compiled step of :mod:`roadload.gym.ecodrive_kernel` -- the simulator core through :mod:`roadload.envs.batch`, the
action mapping, reward terms, done flags, observation (mode ``'state'``) and ``info`` values -- in one compiled loop
over the sub-envs, optionally split over numba threads. Episodes are set up exactly as the single env does (road
drawn from the sub-env's RNG, simulator built from the preset), so with the same seeds every sub-env's trajectory
equals the single env's (tests/gym/test_vector.py).

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
are per-vehicle Python objects); use ``vectorization_mode='sync'`` for those. Scheduled effects (ramps) run in the
compiled core and are batched.
"""

from __future__ import annotations

import os
import warnings
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.utils import seeding
import numba
from numba import prange

from roadload.envs import Simulator
from roadload.gym.actions import BOUND_TOLERANCE, validate_actions
from roadload.gym.config import SPACE_FIELDS_ECODRIVE, EcoDriveConfig, GymConfigError, make_config, updated_config
from roadload.gym.ecodrive import EcoBatch, observation_factory
from roadload.gym.ecodrive_kernel import (COST_NAMES, INFO_ROWS, INFO_SCALARS, I_COSTS, I_RETURN, I_TERMS,
                                          command_wheel_force, advance_vehicle, kernel, state_of, step_range,
                                          wheel_force)

# --------------------------------------------------------------------------------------------- compiled kernels
@kernel(parallel=True)
def _step_threads(n_chunks, active, u, fleet, eco, out):
    """step_range over n_chunks contiguous blocks of sub-envs, one numba thread each."""
    n = active.shape[0]
    for c in prange(n_chunks):
        step_range(c * n // n_chunks, (c + 1) * n // n_chunks, active, u, fleet, eco, out)


@kernel()
def _advance_range(lo, hi, active, u, fleet, settings):
    """The bare batched physics of vehicles lo..hi-1: for every active vehicle i, the wheel force of command u[i]
    (DriveScales in the SETTINGS record settings[0]) held for n substeps of the simulator core."""
    cfg = settings[0]
    for i in range(lo, hi):
        if active[i]:
            command_wheel_force(fleet, i, wheel_force(cfg, u[i], state_of(fleet, i).speed), np.nan)
            advance_vehicle(fleet, i, cfg.n_substeps)


@kernel()
def _actions_in_bounds(u, tol):
    """True when every action is finite and inside [-1 - tol, 1 + tol] (the fast path of the action check)."""
    for j in range(u.size):
        if not (u[j] >= -1.0 - tol and u[j] <= 1.0 + tol):  # NaN fails too
            return False
    return True


@kernel(parallel=True)
def _advance_threads(n_chunks, active, u, fleet, settings):
    n = active.shape[0]
    for c in prange(n_chunks):
        _advance_range(c * n // n_chunks, (c + 1) * n // n_chunks, active, u, fleet, settings)


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
        observation = observation_factory(cfg)
        self.layout = observation.layout
        self.single_observation_space = observation.space()
        self._action_box = gym.spaces.Box(-1.0, 1.0, shape=(1,), dtype=np.float32)
        self.single_action_space = self._action_box
        self.observation_space = gym.vector.utils.batch_space(self.single_observation_space, n)
        self.action_space = gym.vector.utils.batch_space(self.single_action_space, n)
        self.batch = EcoBatch(n, cfg, observation)
        self._configs: list[EcoDriveConfig] = [cfg] * n
        self._rngs: list[np.random.Generator] = [seeding.np_random()[0] for _ in range(n)]
        self._needs_reset = np.ones(n, dtype=bool)  # step() before reset() resets
        self._all_active = np.ones(n, dtype=bool)
        self.batch.setup(0, cfg, cfg.road_seed if cfg.road_seed is not None else cfg.road_seed_range[0], 0)

    # ------------------------------------------------------------------ checks
    @staticmethod
    def _check_batchable(cfg: EcoDriveConfig) -> None:
        if not observation_factory(cfg).batched:
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
        self.batch.setup(i, cfg, road_seed, sim_seed)

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
        return self.batch.obs.copy(), self._info(mask, with_terms=False)

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
        stepper = None if self.threads == 1 else lambda *args: _step_threads(self.threads, *args)
        reward, term, trunc, info_block, ints = self.batch.step(active, u, stepper)
        info = self._info_dict(info_block, ints, np.ones(n, dtype=bool), active)
        if self.autoreset_mode == gym.vector.AutoresetMode.NEXT_STEP:
            self._needs_reset = term | trunc
            return self.batch.obs.copy(), reward, term, trunc, info
        # same step: reset the finished sub-envs now, report their last observation / info
        done = term | trunc
        obs = self.batch.obs.copy()
        if done.any():
            final_obs = np.where(done[:, None], obs, 0.0).astype(np.float32)
            for i in np.flatnonzero(done):
                self._reset_one(int(i), None, None)
            obs = self.batch.obs.copy()
            fresh = self._info(done, with_terms=False)
            info = {**fresh, "final_obs": final_obs, "_final_obs": done, "final_info": info, "_final_info": done}
        return obs, reward, term, trunc, info

    def _info_dict(self, block: np.ndarray, ints: np.ndarray, mask: np.ndarray,
                   with_terms: np.ndarray | None) -> dict[str, Any]:
        """gymnasium vector info from the info block: one array per key of the single env's info (row views of
        the block, fresh every step), '_key' = which sub-envs have it; 'terms' / 'costs' when any sub-env
        stepped (with_terms: those that did)."""
        info: dict[str, Any] = {k: (block[r] if r >= 0 else ints[-1 - r]) for k, r in INFO_ROWS}
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
        block, ints = self.batch.info_blocks()
        return self._info_dict(block, ints, mask, None)

    # ------------------------------------------------------------------ benchmark hook
    def bare_physics_step(self, actions: np.ndarray) -> None:
        """Only the batched physics of one env step (no reward, observation, info, autoreset): the reference the
        benchmark compares the env step with."""
        u = np.asarray(actions, dtype=np.float64).reshape(self.num_envs)
        fleet, settings = self.batch.fleet_records(), self.batch.settings
        if self.threads > 1:
            _advance_threads(self.threads, self._all_active, u, fleet, settings)
        else:
            _advance_range(0, self.num_envs, self._all_active, u, fleet, settings)

    @property
    def sub_simulators(self) -> list[Simulator | None]:
        """The simulator objects the episodes were set up from (their state is NOT advanced by step())."""
        return list(self.batch.simulators)


def make_vector_env(num_envs: int = 1, **kwargs: Any) -> EcoDriveVectorEnv:
    """The ``vector_entry_point`` of roadload/EcoDrive-v0 (``gymnasium.make_vec`` passes num_envs + env kwargs)."""
    kwargs.pop("max_episode_steps", None)
    if "render_mode" in kwargs and kwargs["render_mode"] is not None:
        raise GymConfigError("render_mode: the native vector env does not render; use vectorization_mode='sync'")
    kwargs.pop("render_mode", None)
    return EcoDriveVectorEnv(num_envs=num_envs, **kwargs)


__all__ = ["EcoDriveVectorEnv", "make_vector_env", "COST_NAMES", "INFO_SCALARS", "openmp_wait_policy"]
