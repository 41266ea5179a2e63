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
I <- max(0, I + k_i e), lambda = max(0, k_p e + I). The multiplier prices a metre
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
"""

from __future__ import annotations

import json
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


class SpeedConstraint(gym.vector.VectorWrapper):
    """The training reward r + (lambda - mu) * price * dx with lambda a PI-controlled Lagrange multiplier on the mean
    speed's floor (1 + margin) v_ref and, when ``upper`` is given, mu one on its ceiling (1 + upper) v_ref (module
    docstring). ``price`` [reward per m] = the env's reward scale x its progress weight; ``step_time`` [s];
    ``window`` env steps at least between multiplier updates (PPO's n_steps: one value per rollout);
    ``multiplier``: lambda's start value."""

    def __init__(self, env: gym.vector.VectorEnv, reference: float, price: float, step_time: float,
                 window: int, margin: float = 0.0, k_p: float = 20.0, k_i: float = 20.0,
                 multiplier: float = 0.0, upper: float | None = None) -> None:
        if not reference > 0 or not price > 0 or not step_time > 0:
            raise RLError(f"speed constraint: expected a reference speed [m/s], price [1/m] and step time [s] > 0, "
                          f"got {reference}, {price}, {step_time}")
        if window < 1 or not -0.2 <= margin <= 0.2:
            raise RLError(f"speed constraint: expected window >= 1 step and -0.2 <= margin <= 0.2 (relative), got "
                          f"{window}, {margin}")
        if upper is not None and not margin < upper <= 0.2:
            raise RLError(f"speed constraint: expected margin < upper <= 0.2 (relative speeds over the reference), "
                          f"got margin {margin}, upper {upper}")
        super().__init__(env)
        self.target = reference * (1.0 + margin)
        self.ceiling = None if upper is None else reference * (1.0 + upper)
        self.reference = reference
        self.price, self.step_time, self.window = price, step_time, window
        self.k_p, self.k_i = k_p, k_i
        self.multiplier = self.integral = max(0.0, multiplier)
        self.upper_multiplier = self.upper_integral = 0.0
        self._episode_distance = np.zeros(self.num_envs)
        self._episode_steps = np.zeros(self.num_envs, dtype=np.int64)
        self._distance = 0.0  # of the episodes ended in this window
        self._time = 0.0
        self._steps = 0
        self.history: list[tuple[float, float]] = []
        """(mean speed of the window's ended episodes [m/s], lambda - mu after it) per update."""

    @classmethod
    def band(cls, env: gym.vector.VectorEnv, reference: float, price: float, step_time: float, window: int,
             band: SpeedBand) -> "SpeedConstraint":
        """The two-sided constraint holding the mean speed in ``band`` around ``reference`` [m/s]."""
        return cls(env, reference, price, step_time, window, margin=band.lower, k_p=band.k_p, k_i=band.k_i,
                   upper=band.upper)

    def step(self, actions):
        obs, reward, terminated, truncated, info = self.env.step(actions)
        dx = step_distance(info, terminated | truncated)
        shaped = reward + (self.multiplier - self.upper_multiplier) * self.price * dx
        done = terminated | truncated
        self._episode_distance += dx
        self._episode_steps += 1
        if done.any():
            self._distance += float(self._episode_distance[done].sum())
            self._time += float(self._episode_steps[done].sum()) * self.step_time
            self._episode_distance[done] = 0.0
            self._episode_steps[done] = 0
        self._steps += 1
        if self._steps >= self.window and self._time > 0.0:
            self.update(self._distance / self._time)
            self._distance, self._time, self._steps = 0.0, 0.0, 0
        return obs, shaped, terminated, truncated, info

    def update(self, speed: float) -> float:
        """The PI step of the multipliers after a window whose mean speed was ``speed`` [m/s]; returns the net
        multiplier lambda - mu (lambda alone without a ceiling)."""
        error = (self.target - speed) / self.reference
        self.integral = max(0.0, self.integral + self.k_i * error)
        self.multiplier = max(0.0, self.k_p * error + self.integral)
        if self.ceiling is not None:
            excess = (speed - self.ceiling) / self.reference
            self.upper_integral = max(0.0, self.upper_integral + self.k_i * excess)
            self.upper_multiplier = max(0.0, self.k_p * excess + self.upper_integral)
        net = self.multiplier - self.upper_multiplier
        self.history.append((speed, net))
        return net
