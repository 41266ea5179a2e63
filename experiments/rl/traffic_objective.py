"""The training objective of PPO on ``roadload/EcoTraffic-v0``: the env's reward with a mean-speed constraint.

Why a constraint: under EcoTraffic-v0's reward (1000 J per metre of progress, source energy, 0.9 x the change
of mechanical energy) the IDM follower's own family of settings is nearly flat. Along it (time gap 1.2-1.8 s,
desired speed 23-27 m/s, no feed-forward; 50 held-out episodes, safety layer on) one km/h of mean speed costs
1.0-1.9 Wh/km, and the return moves by 0.4 at most between 73.5 and 75.3 km/h. So "a little slower for a little less
energy" is almost free in the return, and PPO drifts there. That is not an eco-driving win. The task is less
energy for the same trip time.

The wrapper (:class:`SpeedConstraint`) trains on the env reward plus a Lagrange multiplier lambda >= 0 times the
progress term, r' = r + lambda * scale * w_progress * dx (dx the step's distance [m]). lambda is a PI controller on
the constraint mean speed >= (1 + margin) * v_ref (Stooke, Achiam & Abbeel 2020, "Responsive safety in RL by PID
Lagrangian methods"). v_ref is the IDM follower's mean speed on training episodes of the same configuration
(:func:`reference_speed`). After every ``window`` steps (PPO's rollout) in which episodes ended, with
e = ((1 + margin) v_ref - v) / v_ref and v the mean speed of those whole episodes (a window's steps alone would
mix the slow start of an episode with the cruise in proportions that change from window to window):
I <- min(I_max, max(0, I + k_i e)), lambda = max(0, k_p e + I) (I_max the anti-windup cap, none by default:
while the policy cannot follow, the integral would keep pricing a metre higher, and it takes as many windows above
the floor to unwind as it rose). The multiplier prices a metre
at exactly what keeps the mean speed at the reference. At that speed the policy can only gain by spending less
energy. The env's reward and its figures are unchanged; evaluation reports both.

Why the trip's end is terminal in training (:class:`TripEnd`): SB3 bootstraps a truncated episode with the critic's
value of its last state. Under the IDM follower a longer gap to the leader is worth future progress (the follower
closes it later), so the critic counts metres given up by braking early as metres banked. Braking harder at the
start (regenerating the start's kinetic energy) then looks free, and the multiplier cannot price it. Measured on
held-out episodes, that policy (residual on the follower, multiplier on) was 13.4 m behind the follower after 40 s,
at the same final speed. The evaluation and the task are 40 s trips, so training ends them there, without a
bootstrap. The observation has no clock, so the policy cannot time a coast to the cutoff.

Why a two-sided constraint (:class:`SpeedBand`): with the floor alone PPO chose to drive 1.2-1.6 % faster than the
follower (the reward's 1000 J per metre pays more for the metres than their energy costs) and spent 1.0 Wh/km more
on the stopping-gap spawn. Held to a band (1 + lower) v_ref <= v <= (1 + upper) v_ref, a second multiplier
mu >= 0 takes the price of a metre down when the mean speed is above the band: r' = r + (lambda - mu) * price * dx,
mu by the same PI rule on e = (v - (1 + upper) v_ref) / v_ref. Inside the band the last metre is worth what the
multipliers leave of it, so the policy can only gain by spending less energy at the follower's pace. A fixed time
weight that makes speed worthless would do the same only if the value of a metre against energy were known per
scenario (it is 1.0-1.9 Wh/km per km/h on the follower's own settings, and differs in dense traffic); the
multipliers find it from the measured speed, per scenario, with no tuning to a figure.

Why a paired reference (``follower=``, :class:`PairedFollower`): in training a window's mean speed scatters 0.6-0.9 %
from rollout to rollout with the traffic alone (2-3x the band's width) and the fixed v_ref of 64 training episodes
is known to +-0.5 %, so the multipliers chased the traffic's noise and two of three dense seeds landed slower than
the follower. With the follower, an IDM vector env seeded like the training env, stepped in lockstep, drives the
same episodes: the native env draws sub-env i's episodes (traffic, road, effect noise) from sub-env i's own
generator at reset only, so episode k of sub-env i is the same traffic in both envs whatever the ego does. Each
ended training episode is paired with the follower's episode of the same sub-env and index, and the PI rule acts on
the window's v / v_ref,window with both the sums over the same episodes: the traffic's scatter cancels in the ratio.
Why lockstep rather than a cache of per-seed follower speeds: the vector env draws the episodes inside its
generators (no per-episode seed to key a cache on), and one more native step of 32 sub-envs plus the IDM command
costs a few % of a PPO step; a reward relative to the follower's per-step progress would need the two drives to
stay step-aligned, which they do not once the policy's gap differs.

Why a relative reward (``relative=True``, with the follower): the critic cannot foresee the traffic (cut-ins, the
leader's braking), and what it cannot foresee stays in the advantage. Measured on a trained dense-traffic policy
(32 sub-envs x 1,200 steps, stochastic actions, the net multiplier 0), the return-to-go less the critic's value
scattered with sd 3.5 reward units at episode starts and 4.3 over all steps, while the return-to-go less the paired
follower's on the same episode scattered 0.65 and 0.39: the traffic adds 30-120x the variance of what the policy does,
and the limit's whole saving is ~1.4 units per episode. The follower's reward stream is a function of the episode
seeds alone (its own env, its own actions), not of the policy's actions, so subtracting its shaped reward of the
same step, r' - r'_follower, leaves every policy gradient's expectation unchanged (a control variate: the
policy's action is independent of the follower's future given the observation) and the optimum the same policy;
the value the critic has to learn is then the difference to the follower, 0 at every episode's start (both start
in the same state). Summed over an episode it is the paired difference the evaluation reports.
"""

from __future__ import annotations

import json
import math
from typing import Any, Callable, cast

import gymnasium as gym
import numpy as np
from pydantic import BaseModel, ConfigDict, Field, model_validator

from roadload.gym.config import EcoTrafficConfig, GymConfigError, make_config
from roadload.gym.traffic import EcoTrafficVectorEnv

from .common import RLError

REFERENCE_SEED = 90_000
"""First episode seed of the reference-speed run (training episodes are drawn by the env; held-out start at
50000)."""


def step_distance(info: dict[str, Any], done: np.ndarray) -> np.ndarray:
    """Distance [m] each sub-env drove in the step. With same-step autoreset a step where some sub-env finished
    reports every sub-env's terms in ``final_info`` (the top level then holds the new episodes' reset info)."""
    if done.any():
        info = info["final_info"]
    terms = info.get("terms")
    if terms is None:
        return np.zeros(done.shape[0])
    return np.where(info["_terms"], terms["progress"], 0.0).astype(np.float64)


def reference_speed(policy: Callable[[np.ndarray], np.ndarray], env_config: dict[str, Any], n_envs: int = 32,
                    episodes_per_env: int = 2, seed: int = REFERENCE_SEED) -> float:
    """Mean speed [m/s] of ``policy`` (the IDM follower) on training episodes: the distance over the driving time of
    ``n_envs`` x ``episodes_per_env`` episodes, measured like :class:`SpeedConstraint` measures the policy's."""
    cfg = make_config(EcoTrafficConfig, env_config)
    steps = int(round(cfg.duration * cfg.policy_frequency)) * episodes_per_env
    env = EcoTrafficVectorEnv(n_envs, config=env_config, autoreset_mode="same_step")
    obs, _ = env.reset(seed=seed)
    dist = 0.0
    for _ in range(steps):
        obs, _, term, trunc, info = env.step(policy(obs))
        dist += float(step_distance(info, term | trunc).sum())
    env.close()
    return dist / (steps * n_envs / cfg.policy_frequency)


class TripEnd(gym.vector.VectorWrapper):
    """The time limit (or the road's end) as the end of the trip in training: truncated episodes are reported as
    terminated, so the learner does not bootstrap their value beyond the trip (module docstring)."""

    def step(self, actions):
        obs, reward, terminated, truncated, info = self.env.step(actions)
        return obs, reward, terminated | truncated, np.zeros_like(truncated), info


class SpeedBand(BaseModel):
    """The mean-speed band of the two-sided constraint, relative to the IDM follower's mean speed v_ref:
    (1 + lower) v_ref <= v <= (1 + upper) v_ref, and the multipliers' PI gains (module docstring)."""

    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)
    lower: float = Field(0.001, ge=-0.2, le=0.2, description="lowest mean speed over the follower's, relative "
                         "[1] (0.001 = +0.1 %)")
    upper: float = Field(0.004, ge=-0.2, le=0.2, description="highest mean speed over the follower's, relative "
                         "[1] (0.004 = +0.4 %)")
    k_p: float = Field(20.0, ge=0.0, le=1000.0, description="proportional gain per relative speed error [1]")
    k_i: float = Field(20.0, ge=0.0, le=1000.0, description="integral gain per relative speed error and window [1]")
    integral_max: float | None = Field(None, gt=0.0, le=1000.0, description="anti-windup: the largest value each "
                                       "multiplier's integral may hold [1] (1.0: the integral alone prices a metre "
                                       "at most 2x the env's pay); None: no cap")

    @model_validator(mode="after")
    def _ordered(self) -> "SpeedBand":
        if not self.lower < self.upper:
            raise ValueError(f"lower ({self.lower}) must be below upper ({self.upper}): the band's relative speeds "
                             f"over the follower's [1]")
        return self


def speed_band(text: str | dict[str, Any]) -> SpeedBand:
    """A :class:`SpeedBand` from JSON text or a dict; raises :class:`RLError` naming each bad field, its value and
    the expected range with its unit."""
    try:
        data = json.loads(text) if isinstance(text, str) else text
    except json.JSONDecodeError as exc:
        raise RLError(f"speed band: expected JSON text such as '{{\"lower\": 0.001, \"upper\": 0.004}}', got "
                      f"{text!r} ({exc.msg})") from None
    try:
        return cast(SpeedBand, make_config(cast(Any, SpeedBand), data))
    except GymConfigError as exc:
        raise RLError(str(exc)) from None


class EpisodeAccumulator:
    """Per sub-env bookkeeping of the running episodes: the distance [m] and steps driven so far, and the
    (distance [m], time [s]) of each ended episode in the order they ended, until taken (``ended[i]``)."""

    def __init__(self, num_envs: int, step_time: float) -> None:
        if num_envs < 1 or not step_time > 0:
            raise RLError(f"episode accumulator: expected num_envs >= 1 and step_time > 0 s, got {num_envs}, "
                          f"{step_time}")
        self.step_time = step_time
        self._distance = np.zeros(num_envs)
        self._steps = np.zeros(num_envs, dtype=np.int64)
        self.ended: list[list[tuple[float, float]]] = [[] for _ in range(num_envs)]

    def reset(self) -> None:
        """Every sub-env starts a new episode; the ended ones not yet taken are dropped."""
        self._distance[:] = 0.0
        self._steps[:] = 0
        self.ended = [[] for _ in range(self._distance.shape[0])]

    def add(self, info: dict[str, Any], done: np.ndarray) -> np.ndarray:
        """Counts one vector step (``info`` and ``done`` of a same-step autoreset env) and returns each sub-env's
        distance [m] in it (:func:`step_distance`)."""
        dx = step_distance(info, done)
        self._distance += dx
        self._steps += 1
        for i in np.flatnonzero(done):
            self.ended[i].append((float(self._distance[i]), float(self._steps[i]) * self.step_time))
        self._distance[done] = 0.0
        self._steps[done] = 0
        return dx


class PairedFollower:
    """The IDM follower (``policy``) driving the training env's episodes in lockstep on its own vector env
    ``env`` (same configuration and sub-env count, seeded like the training env at every reset; module docstring).
    Its :class:`EpisodeAccumulator` (``episodes``) keeps the (distance [m], time [s]) of its ended episodes per
    sub-env, for :class:`SpeedConstraint` to pair with the training env's episodes of the same index."""

    def __init__(self, env: gym.vector.VectorEnv, policy: Callable[[np.ndarray], np.ndarray],
                 step_time: float) -> None:
        mode = getattr(env, "autoreset_mode", None)
        if mode != gym.vector.AutoresetMode.SAME_STEP:
            raise RLError(f"paired follower: autoreset_mode: expected 'same_step' (the training env's), got {mode!r}")
        self.env, self.policy, self.step_time = env, policy, step_time
        self._obs: np.ndarray | None = None
        self.episodes = EpisodeAccumulator(env.num_envs, step_time)

    def reset(self, seed: int | list[int | None] | None, options: dict[str, Any] | None = None) -> None:
        """New episodes seeded as the training env's; unseeded resets are refused (the follower could then drive
        other episodes than the policy)."""
        seeds = seed if isinstance(seed, list) else [seed]
        if any(s is None for s in seeds):
            raise RLError(f"paired follower: reset seed: expected an integer seed for every sub-env (the follower "
                          f"replays the training env's episodes from it), got {seed!r}")
        # gymnasium annotates VectorEnv.reset(seed: int | None); its vector envs take one seed per sub-env too
        self._obs, _ = self.env.reset(seed=seed, options=options)  # type: ignore[arg-type]
        self.episodes.reset()

    def step(self) -> tuple[np.ndarray, np.ndarray]:
        """One lockstep vector step; returns the follower's env reward and distance [m] per sub-env."""
        if self._obs is None:
            raise RLError("paired follower: step before reset")
        self._obs, reward, terminated, truncated, info = self.env.step(self.policy(self._obs))
        return np.asarray(reward, dtype=np.float64), self.episodes.add(info, terminated | truncated)

    def close(self) -> None:
        self.env.close()


class SpeedConstraint(gym.vector.VectorWrapper):
    """The training reward r + (lambda - mu) * price * dx with lambda a PI-controlled Lagrange multiplier on the mean
    speed's floor (1 + margin) v_ref and, when ``upper`` is given, mu one on its ceiling (1 + upper) v_ref (module
    docstring). ``price`` [reward per m] = the env's reward scale x its progress weight; ``step_time`` [s];
    ``window`` env steps at least between multiplier updates (PPO's n_steps: one value per rollout);
    ``multiplier``: lambda's start value. With ``follower`` (:class:`PairedFollower`) the band is around the
    follower's mean speed on the window's own episodes instead of the fixed ``reference`` (which then only names
    the scale in the history and the metadata; module docstring); with ``relative`` too the reward is that less
    the follower's reward r_f + (lambda - mu) * price * dx_f of the same step (module docstring)."""

    def __init__(self, env: gym.vector.VectorEnv, reference: float, price: float, step_time: float,
                 window: int, margin: float = 0.0, k_p: float = 20.0, k_i: float = 20.0,
                 multiplier: float = 0.0, upper: float | None = None,
                 follower: PairedFollower | None = None, relative: bool = False,
                 integral_max: float | None = None) -> None:
        if not reference > 0 or not price > 0 or not step_time > 0:
            raise RLError(f"speed constraint: expected a reference speed [m/s], price [1/m] and step time [s] > 0, "
                          f"got {reference}, {price}, {step_time}")
        if window < 1 or not -0.2 <= margin <= 0.2:
            raise RLError(f"speed constraint: expected window >= 1 step and -0.2 <= margin <= 0.2 (relative), got "
                          f"{window}, {margin}")
        if upper is not None and not margin < upper <= 0.2:
            raise RLError(f"speed constraint: expected margin < upper <= 0.2 (relative speeds over the reference), "
                          f"got margin {margin}, upper {upper}")
        if follower is not None and follower.env.num_envs != env.num_envs:
            raise RLError(f"speed constraint: follower num_envs: expected the training env's {env.num_envs} "
                          f"sub-envs (episodes are paired per sub-env), got {follower.env.num_envs}")
        if integral_max is not None and not 0 < integral_max <= 1000:
            raise RLError(f"speed constraint: integral_max: expected 0 < integral_max <= 1000 (multiplier units [1]) "
                          f"or None, got {integral_max}")
        if relative and follower is None:
            raise RLError("speed constraint: relative reward: needs the paired follower (its reward on the same "
                          "episodes is what is subtracted), got follower None")
        if follower is not None and abs(follower.step_time - step_time) > 1e-12:
            raise RLError(f"speed constraint: follower step_time: expected the training env's {step_time} s, got "
                          f"{follower.step_time} s")
        super().__init__(env)
        self.margin, self.upper = margin, upper
        self.reference = reference
        self.follower, self.relative = follower, relative
        self.price, self.step_time, self.window = price, step_time, window
        self.k_p, self.k_i = k_p, k_i
        self.integral_max = math.inf if integral_max is None else integral_max
        self.multiplier = self.integral = max(0.0, multiplier)
        self.upper_multiplier = self.upper_integral = 0.0
        self.episodes = EpisodeAccumulator(self.num_envs, step_time)  # ended ones wait for the follower's
        self._distance = self._time = 0.0  # of the (paired) episodes ended in this window
        self._ref_distance = self._ref_time = 0.0  # the follower's on the same episodes
        self._steps = 0
        self.history: list[tuple[float, float, float]] = []
        """(mean speed of the window's ended episodes [m/s], the reference speed they are held to [m/s],
        lambda - mu after it) per update."""

    @classmethod
    def band(cls, env: gym.vector.VectorEnv, reference: float, price: float, step_time: float, window: int,
             band: SpeedBand, follower: PairedFollower | None = None, relative: bool = False) -> "SpeedConstraint":
        """The two-sided constraint holding the mean speed in ``band`` around ``reference`` [m/s] (around the
        follower's on the same episodes with ``follower``)."""
        return cls(env, reference, price, step_time, window, margin=band.lower, k_p=band.k_p, k_i=band.k_i,
                   upper=band.upper, follower=follower, relative=relative, integral_max=band.integral_max)

    @property
    def target(self) -> float:
        """The floor (1 + margin) v_ref [m/s] at the fixed reference."""
        return self.reference * (1.0 + self.margin)

    @property
    def ceiling(self) -> float | None:
        """The ceiling (1 + upper) v_ref [m/s] at the fixed reference, None without one."""
        return None if self.upper is None else self.reference * (1.0 + self.upper)

    def reset(self, *, seed: int | list[int | None] | None = None, options: dict[str, Any] | None = None):
        # gymnasium annotates VectorEnv.reset(seed: int | None); its vector envs take one seed per sub-env too
        obs, info = self.env.reset(seed=seed, options=options)  # type: ignore[arg-type]
        if self.follower is not None:
            self.follower.reset(seed, options)
        self.episodes.reset()
        return obs, info

    def step(self, actions):
        obs, reward, terminated, truncated, info = self.env.step(actions)
        dx = self.episodes.add(info, terminated | truncated)
        net = self.multiplier - self.upper_multiplier
        shaped = reward + net * self.price * dx
        if self.follower is not None:
            reward_ref, dx_ref = self.follower.step()
            if self.relative:  # the follower's shaped reward of the same step: independent of the policy's actions
                shaped = shaped - (reward_ref + net * self.price * dx_ref)
        self._pair()
        self._steps += 1
        if self._steps >= self.window and self._time > 0.0:
            reference = self._ref_distance / self._ref_time if self.follower is not None else None
            self.update(self._distance / self._time, reference)
            self._distance = self._time = self._ref_distance = self._ref_time = 0.0
            self._steps = 0
        return obs, shaped, terminated, truncated, info

    def _pair(self) -> None:
        """Counts each ended episode into the window, with the follower: once the follower's episode of the same
        sub-env and index has ended too (one that crashed early waits for the other)."""
        for i in range(self.num_envs):
            mine = self.episodes.ended[i]
            theirs = None if self.follower is None else self.follower.episodes.ended[i]
            while mine and (theirs is None or theirs):
                d, t = mine.pop(0)
                self._distance += d
                self._time += t
                if theirs is not None:
                    d_ref, t_ref = theirs.pop(0)
                    self._ref_distance += d_ref
                    self._ref_time += t_ref

    def update(self, speed: float, reference: float | None = None) -> float:
        """The PI step of the multipliers after a window whose mean speed was ``speed`` [m/s], against
        ``reference`` [m/s] (the follower's on the same episodes; the fixed reference when None); returns the net
        multiplier lambda - mu (lambda alone without a ceiling)."""
        ref = self.reference if reference is None else reference
        if not ref > 0:
            raise RLError(f"speed constraint: reference speed: expected > 0 m/s, got {ref}")
        error = (1.0 + self.margin) - speed / ref
        self.integral = min(self.integral_max, max(0.0, self.integral + self.k_i * error))
        self.multiplier = max(0.0, self.k_p * error + self.integral)
        if self.upper is not None:
            excess = speed / ref - (1.0 + self.upper)
            self.upper_integral = min(self.integral_max, max(0.0, self.upper_integral + self.k_i * excess))
            self.upper_multiplier = max(0.0, self.k_p * excess + self.upper_integral)
        net = self.multiplier - self.upper_multiplier
        self.history.append((speed, ref, net))
        return net

    def close(self, **kwargs: Any) -> None:
        if self.follower is not None:
            self.follower.close()
        super().close(**kwargs)
