"""Where an eco-driving policy could save energy against the IDM follower on ``roadload/EcoTraffic-v0``: rule-based
variants of the follower, each testing one physical lever, on the held-out episodes of the PPO evaluation and
paired with the follower by episode (roadload.experiments.rl.traffic_training.paired_differences).

    python scripts/traffic_levers.py --episodes 50     # ~3 min CPU
    python scripts/traffic_levers.py --quick           # CI smoke run (2 episodes)

Levers (u the follower's command, roadload.experiments.rl.highway.idm_policy):

- the follower's own settings (time gap, desired speed, feed-forward): its speed-energy line;
- ``coast``: u clipped at 0 from below, i.e. the speed shed from the spawn's 25 m/s by rolling and air resistance
  instead of regenerative braking (the kinetic energy goes straight into the road load, without the motor and
  battery losses of braking and driving again);
- ``coast outside the envelope``: the same while the gap one second ahead (at the current closing speed) is more
  than ``margin`` above the safety layer's envelope gap (roadload.gym.traffic.envelope_gap), so the layer's braking
  is not triggered;
- ``grade``: u less ``gain`` x the grade force m g sin(theta) over the traction scale, so the speed falls uphill
  and rises downhill (the gap to the leader as the buffer) instead of the motor lifting and the brakes lowering the
  car;
- ``anticipate cut-ins``: a neighbour ahead on another lane whose lateral speed (the Kinematics block's vy,
  relative to the ego) brings it within half a lane of the ego's path within ``horizon`` seconds is taken as the
  leader already (the follower's IDM on the smaller gap), so the follower starts braking for a cut-in before the
  car is on its lane (the traffic limit, roadload.experiments.rl.traffic_limit, puts most of what a drive at the
  follower's speed could save into the episodes where the follower brakes hard; this lever asks whether a cut-in
  seen coming is that);
- ``regeneration-limited braking``: the follower's braking capped at ``fraction`` of the drive's regeneration limit
  (min(T_regen i / r, P_regen / v); the i3's 50 kW: 2 kN at 25 m/s, where u = -1 asks for 6.9 kN),
  so that it never uses the friction brake on its own; the safety layer still brakes harder where the envelope
  needs it. After the spawn (25 m/s, at the envelope gap behind slower traffic) the follower brakes at up to
  3.5 m/s^2 and re-accelerates, in the episodes where the traffic limit finds most of the headroom;
- ``constant-acceleration heuristic``: the follower's IDM acceleration blended with the CAH acceleration of the
  ACC model (Kesting, Treiber & Helbing 2010, leader acceleration taken as 0): a_CAH = -(v - v_l)+^2 / (2 gap),
  a = a_IDM where a_IDM >= a_CAH, else (1 - c) a_IDM + c (a_CAH + b tanh((a_IDM - a_CAH) / b)), c = 0.99,
  b = 2 m/s^2. IDM over-reacts to a large closing speed at a gap that is long enough (the spawn, a cut-in well
  ahead); the CAH brakes only as much as the closing speed needs;
- ``pulse and glide``: where 0 < u < pulse, the command alternates between 0 and ``pulse`` with u's mean (a
  first-order sigma-delta modulator: it pulses whenever the accumulated command reaches ``pulse``), driving the
  motor at higher torque for part of the time.
"""

from __future__ import annotations

import argparse
import math
from typing import Any, Callable

import numpy as np
import pandas as pd

from roadload.controllers.vehicle_models import energy_model_from_spec
from roadload.gym.config import EcoTrafficConfig, make_config
from roadload.gym.ecodrive import DriveScales
from roadload.gym.traffic import envelope_gap
from roadload.gym.traffic_model import LANE_WIDTH, LENGTH, MAX_SPEED, PERCEPTION_DISTANCE
from roadload.presets import get_preset
from roadload.tables import markdown_table

from .common import json_object_option
from .highway import _indices, idm_policy
from .traffic_training import TRAFFIC_TRAIN_CONFIG, evaluate_traffic, paired_differences, summarise_traffic

Policy = Callable[[np.ndarray], np.ndarray]


def coast_policy(cfg: EcoTrafficConfig, margin: float | None = None) -> Policy:
    """The follower, coasting (u = 0) where it would brake; with ``margin`` [m] only while the gap one second
    ahead is more than margin above the envelope gap (module docstring)."""
    idm = idm_policy(cfg)
    idx = _indices(cfg)
    (kv, sv), (kg, sg), (kc, sc) = idx["v"], idx["front_gap"], idx["front_closing_speed"]
    sh = cfg.shield

    def policy(obs: np.ndarray) -> np.ndarray:
        u = idm(obs)
        if u[0] >= 0.0:
            return u
        if margin is not None:
            v, gap, closing = obs[kv] * sv, obs[kg] * sg, obs[kc] * sc
            need = envelope_gap(v, max(v - closing, 0.0), sh.reaction_time, sh.deceleration, sh.leader_deceleration,
                                sh.margin)
            if gap - closing * 1.0 - need <= margin:
                return u
        return np.zeros_like(u)
    return policy


def grade_policy(cfg: EcoTrafficConfig, gain: float) -> Policy:
    """The follower less ``gain`` x m g sin(theta) / (P_max / v): the grade force left to the speed (module
    docstring)."""
    idm = idm_policy(cfg)
    idx = _indices(cfg)
    (kv, sv), (kg, sg) = idx["v"], idx["grade@0m"]
    spec = get_preset(cfg.vehicle)
    weight = spec.body.mass * 9.81
    drive = DriveScales.from_spec(spec)

    def policy(obs: np.ndarray) -> np.ndarray:
        v = float(obs[kv] * sv)
        scale = min(drive.peak_traction_force, drive.peak_power / max(v, 1.0))
        u = idm(obs) - gain * weight * math.sin(float(obs[kg] * sg)) / scale
        return np.clip(u, -1.0, 1.0).astype(np.float32)
    return policy


def anticipation_policy(cfg: EcoTrafficConfig, horizon: float, coast: bool = False) -> Policy:
    """The follower, braking for a neighbour that is changing onto its lane as for its leader (module docstring):
    a vehicle ahead whose relative lateral position dy [m] and speed vy [m/s] give |dy + vy t| < w / 2 for some
    t in [0, horizon] [s] (w the lane width) replaces the observed leader where its gap is smaller. ``coast``:
    instead of braking for it, only lift off (the command at most 0 while the follower's IDM on that gap would
    brake; the follower's own command when that is lower)."""
    idm = idm_policy(cfg)
    idx = _indices(cfg)
    (kg, sg), (kc, sc) = idx["front_gap"], idx["front_closing_speed"]
    rows = [tuple(idx[f"veh{r}_{f}"][0] for f in ("presence", "x", "y", "vx", "vy"))
            for r in range(1, cfg.kinematics_rows)]
    x_range, y_range, v_range = PERCEPTION_DISTANCE, LANE_WIDTH * cfg.lanes_count, 2.0 * MAX_SPEED

    def policy(obs: np.ndarray) -> np.ndarray:
        o = np.array(obs, dtype=np.float64)
        gap, closing = o[kg] * sg, o[kc] * sc
        for kp, kx, ky, kvx, kvy in rows:
            if o[kp] < 0.5:
                continue
            dx, dy, dvx, dvy = o[kx] * x_range, o[ky] * y_range, o[kvx] * v_range, o[kvy] * v_range
            if dx <= LENGTH or abs(dy) < 0.5 * LANE_WIDTH or dy * dvy >= 0.0:
                continue  # behind or alongside, already on the ego's lane, or not moving towards it
            if abs(dy) - 0.5 * LANE_WIDTH <= abs(dvy) * horizon and dx - LENGTH < gap:
                gap, closing = dx - LENGTH, -dvx
        own = idm(obs)
        if gap >= o[kg] * sg:
            return own
        o[kg], o[kc] = gap / sg, closing / sc
        ahead = idm(o.astype(np.float32))
        if not coast:
            return ahead
        return np.minimum(own, 0.0).astype(np.float32) if ahead[0] < 0.0 else own
    return policy


def regen_limited_policy(cfg: EcoTrafficConfig, fraction: float = 1.0) -> Policy:
    """The follower with its command at least -fraction x the regeneration force limit over the full braking force
    (module docstring)."""
    idm = idm_policy(cfg)
    kv, sv = _indices(cfg)["v"]
    drive = DriveScales.from_spec(get_preset(cfg.vehicle))
    energy = energy_model_from_spec(cfg.vehicle)
    regen_force = float(energy.max_regen_force(energy.gear_ratios[0]))

    def policy(obs: np.ndarray) -> np.ndarray:
        v = max(float(obs[kv] * sv), 1.0)
        floor = -fraction * min(regen_force, energy.max_regen_power / v) / drive.full_brake_force
        return np.maximum(idm(obs), floor).astype(np.float32)
    return policy


def cah_policy(cfg: EcoTrafficConfig, coolness: float = 0.99, comfort_decel: float = 2.0) -> Policy:
    """The follower's IDM blended with the constant-acceleration heuristic (module docstring)."""
    idx = _indices(cfg)
    (kv, sv), (kg, sg), (kc, sc) = idx["v"], idx["front_gap"], idx["front_closing_speed"]
    spec = get_preset(cfg.vehicle)
    drive = DriveScales.from_spec(spec)
    mass = spec.body.mass
    idm = idm_policy(cfg, feed_forward=0.0)
    feed_forward = 0.08  # the follower's (idm_policy's default)

    def policy(obs: np.ndarray) -> np.ndarray:
        v, gap, closing = float(obs[kv] * sv), max(float(obs[kg] * sg), 0.1), float(obs[kc] * sc)
        u_idm = float(idm(obs)[0])
        force = min(drive.peak_traction_force, drive.peak_power / max(v, 1.0)) if u_idm >= 0 else drive.full_brake_force
        a_idm = u_idm * force / mass
        a_cah = -max(closing, 0.0) ** 2 / (2.0 * gap)
        if a_idm < a_cah:
            a = (1 - coolness) * a_idm + coolness * (a_cah + comfort_decel * math.tanh((a_idm - a_cah) / comfort_decel))
        else:
            a = a_idm
        force = min(drive.peak_traction_force, drive.peak_power / max(v, 1.0)) if a >= 0 else drive.full_brake_force
        return np.array([np.clip(feed_forward + a * mass / force, -1.0, 1.0)], dtype=np.float32)
    return policy


def pulse_glide_policy(cfg: EcoTrafficConfig, pulse: float) -> Policy:
    """Pulse and glide around the follower's command (module docstring); stateful, one episode after another."""
    idm = idm_policy(cfg)
    state = {"sum": 0.0}

    def policy(obs: np.ndarray) -> np.ndarray:
        u = float(idm(obs)[0])
        if not 0.0 < u < pulse:
            state["sum"] = 0.0
            return np.array([u], dtype=np.float32)
        state["sum"] += u
        if state["sum"] >= pulse:
            state["sum"] -= pulse
            return np.array([pulse], dtype=np.float32)
        return np.array([0.0], dtype=np.float32)
    return policy


def lever_policies(cfg: EcoTrafficConfig) -> dict[str, Policy]:
    """The follower and every lever of the module docstring."""
    return {"IDM follower": idm_policy(cfg),
            "follower, time gap 1.2 s": idm_policy(cfg, time_gap=1.2),
            "follower, time gap 1.8 s": idm_policy(cfg, time_gap=1.8),
            "follower, desired speed 23 m/s": idm_policy(cfg, target_speed=23.0),
            "follower, desired speed 27 m/s": idm_policy(cfg, target_speed=27.0),
            "follower, no feed-forward": idm_policy(cfg, feed_forward=0.0),
            "coast": coast_policy(cfg),
            "coast outside the envelope (5 m)": coast_policy(cfg, 5.0),
            "anticipate cut-ins (1 s)": anticipation_policy(cfg, 1.0),
            "anticipate cut-ins (2 s)": anticipation_policy(cfg, 2.0),
            "anticipate cut-ins by coasting (1 s)": anticipation_policy(cfg, 1.0, coast=True),
            "anticipate cut-ins by coasting (2 s)": anticipation_policy(cfg, 2.0, coast=True),
            "regeneration-limited braking": regen_limited_policy(cfg, 1.0),
            "regeneration-limited braking (0.7)": regen_limited_policy(cfg, 0.7),
            "constant-acceleration heuristic": cah_policy(cfg),
            "grade (gain 0.5)": grade_policy(cfg, 0.5),
            "grade (gain 1)": grade_policy(cfg, 1.0),
            "pulse and glide (0.2)": pulse_glide_policy(cfg, 0.2),
            "pulse and glide (0.4)": pulse_glide_policy(cfg, 0.4)}


def measure_levers(env_config: dict[str, Any] | None = None, episodes: int = 50) -> dict[str, pd.DataFrame]:
    """Summary and paired differences to the follower of every lever on ``episodes`` held-out episodes."""
    config = {**TRAFFIC_TRAIN_CONFIG, **(env_config or {})}
    cfg = make_config(EcoTrafficConfig, config)
    table = evaluate_traffic(lever_policies(cfg), config, episodes)
    return {"summary": summarise_traffic(table), "paired": paired_differences(table)}


def main(argv: list[str] | None = None) -> None:
    """Print the levers' summary and paired tables (``scripts/traffic_levers.py``)."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--episodes", type=int, default=50, help="held-out episodes per policy")
    ap.add_argument("--config", default=None, help="EcoTraffic-v0 config as JSON text over the training default")
    ap.add_argument("--quick", action="store_true", help="tiny run for CI")
    a = ap.parse_args(argv)
    config = json_object_option(ap, a.config)
    if a.quick:
        a.episodes = 2
        config = {"duration": 5.0, "vehicles_count": 10, **config}
    if a.episodes < 2:
        ap.error(f"--episodes: expected >= 2 (a paired interval needs two), got {a.episodes}")
    res = measure_levers(config, a.episodes)
    print(markdown_table(res["summary"], floatfmt=".4g"))
    print(markdown_table(res["paired"], floatfmt=".4g"))
