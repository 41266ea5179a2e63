"""The reference backend of ``roadload/EcoTraffic-v0``: EcoHighway-v0 (highway-env's road, IDM/MOBIL vehicles and
collision handling around roadload's ego) with EcoTraffic-v0's configuration, action, safety layer, observation
and info, so that the same policy and the same measurements run on both backends (fidelity, transfer).

The Kinematics block is highway-env's own ``KinematicObservation`` (features presence, x, y, vx, vy, normalised,
clipped, sorted); the powertrain block is read from the ego's simulator as EcoTraffic-v0 reads it. highway-env's
road is straight: the configuration must say ``curvature=False`` (the curvature entries are then 0). Non-default
``traffic`` parameters are set on every spawned IDM vehicle.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from gymnasium import spaces
from highway_env.envs.common.observation import KinematicObservation, ObservationType
from highway_env.vehicle.behavior import IDMVehicle

from roadload.gym.actions import validate_action
from roadload.gym.config import (SPACE_FIELDS_TRAFFIC, EcoHighwayConfig, EcoTrafficConfig, GymConfigError,
                                 TrafficBehaviour, make_config, updated_config)
from roadload.gym.ecodrive import RouteTable
from roadload.gym.highway import EcoHighwayEnv
from roadload.gym.traffic import GAP_CAP, envelope_command, envelope_gap, traffic_observation_layout
from roadload.gym.traffic_ego import PREVIEW

_HIGHWAY_FIELDS = ("vehicle", "road", "road_seed", "effects", "lanes_count", "vehicles_count", "vehicles_density",
                   "duration", "policy_frequency", "simulation_frequency", "initial_speed", "speed_limit",
                   "lane_changes", "min_time_headway", "reward")


def highway_config(cfg: EcoTrafficConfig) -> EcoHighwayConfig:
    """The EcoHighway-v0 configuration of the same scenario (GymConfigError for what highway-env cannot run)."""
    if cfg.curvature and cfg.road is not None:
        raise GymConfigError("curvature: highway-env's road is straight; the reference backend needs "
                             "curvature=False (EcoTraffic-v0 then drives the same straight road)")
    data = {k: getattr(cfg, k) for k in _HIGHWAY_FIELDS}
    data["reward"] = cfg.reward.model_dump()
    return make_config(EcoHighwayConfig, data)


class _TrafficObservation(ObservationType):
    """EcoTraffic-v0's observation of an EcoHighway-v0 episode."""

    def __init__(self, env: "HighwayTrafficEnv") -> None:
        super().__init__(env)
        cfg = env.traffic_config
        self.layout = traffic_observation_layout(cfg)
        self.scale = np.array([row[2] for row in self.layout])
        self.rows = cfg.kinematics_rows
        self.kinematics = KinematicObservation(env, vehicles_count=self.rows, see_behind=cfg.see_behind)
        self._route_key: Any = None
        self._route: RouteTable | None = None

    def space(self) -> spaces.Space:
        return spaces.Box(-5.0, 5.0, shape=(self.scale.size,), dtype=np.float32)

    def observe(self) -> np.ndarray:
        env: HighwayTrafficEnv = self.env
        ego = env.vehicle
        x = np.zeros(self.scale.size)
        if ego is None or env.road is None or ego.plant is None:
            return x.astype(np.float32)
        self.kinematics.features_range = None  # highway-env sizes the ranges from the ego's road at each call
        x[:self.rows * 5] = self.kinematics.observe().reshape(-1)
        plant = ego.plant
        st = plant.state
        if self._route_key is not plant.road:
            self._route = RouteTable(plant.road, PREVIEW, 1.0, 2.0)
            self._route_key = plant.road
        assert self._route is not None
        look = self._route.look_ahead(st.s)
        lanes = len(env.road.network.all_side_lanes(ego.lane_index))
        gap, closing = ego.front_gap()
        k = self.rows * 5
        x[k:k + 6] = (ego.speed, st.a, ego.command, env.step_energy / env.step_time, st.gear, st.engine_speed)
        k += 6
        n = PREVIEW.size
        x[k:k + n] = look[RouteTable.GRADE]
        x[k + n:k + 2 * n] = look[RouteTable.CURVATURE]
        k += 2 * n
        x[k:k + 3] = (ego.lane_index[2] / max(lanes - 1, 1), min(gap, GAP_CAP), closing)
        if env.traffic_config.neighbour_features:
            x[k + 3:] = self._neighbour_features().reshape(-1)
        return np.clip(x / self.scale, -5.0, 5.0).astype(np.float32)

    def _neighbour_features(self) -> np.ndarray:
        """(rows - 1, features) EcoTrafficConfig.neighbour_features of the Kinematics block's vehicles, in its
        order, from highway-env's own state: the acceleration command, target lane - lane, and the cut-in time into
        the ego's lane (roadload.gym.traffic_model.cut_in_time's rule on IDMVehicle.mobil and its timer)."""
        env: HighwayTrafficEnv = self.env
        cfg = env.traffic_config
        ego = env.vehicle
        cap = 2.0 * cfg.traffic.lane_change_delay
        names = cfg.neighbour_features
        out = np.zeros((self.rows - 1, len(names)))
        if "cut_in_time" in names:
            out[:, names.index("cut_in_time")] = cap
        close = env.road.close_objects_to(ego, env.PERCEPTION_DISTANCE, count=self.rows - 1,
                                          see_behind=cfg.see_behind, sort=True, vehicles_only=True)
        for r, v in enumerate(close):
            values = {"ax": v.action["acceleration"],
                      "lane_change": v.target_lane_index[2] - v.lane_index[2],
                      "cut_in_time": _cut_in_time(env, v, ego.lane_index, cap)}
            out[r] = [values[name] for name in names]
        return out


class HighwayTrafficEnv(EcoHighwayEnv):
    """EcoHighway-v0 in EcoTraffic-v0's configuration and layout (module docstring): ``HighwayTrafficEnv(config)``
    with an EcoTrafficConfig (or dict / keyword overrides)."""

    def __init__(self, config: EcoTrafficConfig | dict | None = None, render_mode: str | None = None,
                 **overrides: Any) -> None:
        self.traffic_config: EcoTrafficConfig = make_config(EcoTrafficConfig, config, **overrides)
        self.step_energy = 0.0
        self.shield_active = False
        super().__init__(config=highway_config(self.traffic_config), render_mode=render_mode)
        self.layout = traffic_observation_layout(self.traffic_config)

    @property
    def step_time(self) -> float:
        return 1.0 / self.traffic_config.policy_frequency

    def define_spaces(self) -> None:
        super().define_spaces()
        self.observation_type = _TrafficObservation(self)
        self.observation_space = self.observation_type.space()

    def _draw_road_seed(self) -> int:
        return int(self.np_random.integers(*self.traffic_config.road_seed_range))

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        if options:
            self.traffic_config = updated_config(self.traffic_config, options, SPACE_FIELDS_TRAFFIC)
            self.typed_config = highway_config(self.traffic_config)
            self.configure(self._highway_dict(self.typed_config))
        self.step_energy = 0.0
        self.shield_active = False
        return super().reset(seed=seed)

    def _reset(self) -> None:
        super()._reset()
        behaviour = self.traffic_config.traffic
        if behaviour != TrafficBehaviour():
            for v in self.road.vehicles[1:]:
                set_behaviour(v, behaviour, self.road.np_random)
        if self.traffic_config.spawn != "highway-env":
            self._spawn_outside_envelope(self.traffic_config.spawn == "stopping-gap")

    def _spawn_outside_envelope(self, lead_at_rest: bool) -> None:
        """EcoTraffic-v0's ``spawn='outside-envelope'``: the ego moved back along its lane to the safety layer's
        envelope gap (roadload.gym.traffic.envelope_gap) behind the vehicle ahead on it; ``'stopping-gap'``
        (``lead_at_rest``): to the envelope's gap behind a vehicle at rest."""
        ego = self.vehicle
        front, _ = self.road.neighbour_vehicles(ego, ego.lane_index)
        if front is None:
            return
        sh = self.traffic_config.shield
        gap = ego.lane_distance_to(front) - 0.5 * (ego.LENGTH + front.LENGTH)
        need = envelope_gap(ego.speed, 0.0 if lead_at_rest else front.speed, sh.reaction_time, sh.deceleration,
                            sh.leader_deceleration, sh.margin)
        if gap < need:
            ego.position = ego.position - np.array([need - gap, 0.0])
            ego.on_state_update()

    def step(self, action):
        a = np.array(validate_action(action, self.action_space), dtype=np.float32)
        self.shield_active = False
        sh = self.traffic_config.shield
        if sh.enabled:
            cap = 1.0
            ego = self.vehicle
            for lane in dict.fromkeys((ego.lane_index, ego.target_lane_index)):
                front, _ = self.road.neighbour_vehicles(ego, lane)
                if front is None:
                    continue
                gap = ego.lane_distance_to(front) - 0.5 * (ego.LENGTH + front.LENGTH)
                v_lead = max(front.speed * math.cos(front.heading - ego.heading), 0.0)
                cap = min(cap, envelope_command(gap, ego.speed, v_lead, sh.reaction_time, sh.deceleration,
                                                sh.leader_deceleration, sh.margin))
            if cap < a[0]:
                a[0] = np.float32(max(cap, -1.0))
                self.shield_active = True
        return super().step(a)

    def _info(self, obs, action=None) -> dict[str, Any]:
        info = super()._info(obs, action)
        info["shield_active"] = self.shield_active
        return info

    def _simulate(self, action=None) -> None:
        super()._simulate(action)
        self.step_energy = float(self.vehicle.log["energy"])


def _cut_in_time(env: "HighwayTrafficEnv", v: IDMVehicle, lane: Any, cap: float) -> float:
    """Time [s] until v turns into ``lane`` (roadload.gym.traffic_model.cut_in_time on highway-env's vehicle)."""
    if v.lane_index == lane:
        return cap
    if v.target_lane_index == lane:
        return 0.0
    if (v.target_lane_index != v.lane_index or abs(v.lane_index[2] - lane[2]) != 1 or abs(v.speed) < 1
            or not env.road.network.get_lane(lane).is_reachable_from(v.position) or not v.mobil(lane)):
        return cap
    return float(min(max(v.LANE_CHANGE_DELAY - v.timer, 0.0), cap))


def set_behaviour(vehicle: IDMVehicle, behaviour: TrafficBehaviour, np_random) -> None:
    """highway-env's IDM / MOBIL constants of one vehicle set to ``behaviour`` (instance attributes), its speed
    exponent re-drawn from delta_range and its decision timer re-phased to the delay."""
    b = behaviour
    vehicle.ACC_MAX = b.max_acceleration
    vehicle.COMFORT_ACC_MAX = b.comfort_acceleration
    vehicle.COMFORT_ACC_MIN = -b.comfort_deceleration
    vehicle.DISTANCE_WANTED = b.jam_distance
    vehicle.TIME_WANTED = b.time_gap
    vehicle.POLITENESS = b.politeness
    vehicle.LANE_CHANGE_MIN_ACC_GAIN = b.lane_change_min_gain
    vehicle.LANE_CHANGE_MAX_BRAKING_IMPOSED = b.lane_change_max_braking
    vehicle.LANE_CHANGE_DELAY = b.lane_change_delay
    vehicle.DELTA_RANGE = list(b.delta_range)
    vehicle.randomize_behavior()
    vehicle.timer = (np.sum(vehicle.position) * np.pi) % b.lane_change_delay


__all__ = ["HighwayTrafficEnv", "highway_config", "set_behaviour"]
