"""``roadload/EcoHighway-v0``: highway-env's road network and IDM/MOBIL traffic around an ego vehicle whose
longitudinal dynamics and energy come from roadload's simulator (drive-train, resistances, grade), not from
highway-env's kinematic acceleration.

Each traffic frame (``simulation_frequency``, default 10 Hz) the ego runs ``100 Hz / simulation_frequency``
physics steps of :class:`roadload.envs.simulator.Simulator` with the held wheel-force command and takes the
resulting speed; highway-env moves it in the plane (its bicycle model, heading from its lane-keeping /
lane-change steering controller) and handles collisions, the traffic and the rendering.

Action (``lane_changes``): 'off' -> Box(-1, 1, (1,)) normalised wheel-force command (the EcoDrive mapping,
:class:`roadload.gym.ecodrive.DriveScales`); 'dict' -> Dict(force=Box(-1, 1, (1,)), lane_change=Discrete(3):
0 keep, 1 left, 2 right); 'box' -> Box(-1, 1, (2,)) whose second entry < -1/3 asks for a left and > 1/3 for a right
lane change (the SB3-trainable form of the mixed action).

Observation: Box (see :func:`highway_observation_layout`): ego speed, acceleration, grade, lane, the gap and
closing speed to the vehicle ahead, then the nearest ``observed_vehicles`` vehicles' presence and relative x, y,
vx, vy in the ego frame, each divided by a documented scale.

Reward: scale * (progress * dx - energy * E_source + mechanical_energy * dM - collision * [crash]
- headway * integral (h_min - h)+ dt - jerk * integral jerk^2 dt - lane_change * [lane change]); raw terms in
``info['terms']``. dM is the change of the ego's mechanical energy over the step, kinetic 0.5 m v^2 plus potential
(the simulator's climbing work m g dh) [J]; its episode sum is the final minus the initial mechanical energy, i.e. a
terminal credit for the speed and height left at the cutoff, paid as they change (without it, braking from the
initial speed and regenerating its kinetic energy beat driving on: docs/results/rl.md). Terminates on a
collision, truncates at ``duration``.
"""

from __future__ import annotations

import math
import os
import warnings
from typing import Any

import numpy as np
from gymnasium import spaces
from highway_env.envs.common.abstract import AbstractEnv
from highway_env.envs.common.action import ActionType
from highway_env.envs.common.observation import ObservationType
from highway_env.road.road import Road, RoadNetwork
from highway_env.utils import class_from_path, near_split
from highway_env.vehicle.controller import ControlledVehicle
from highway_env.vehicle.kinematics import Vehicle

from roadload.gym.actions import validate_action
from roadload.gym.config import SPACE_FIELDS_HIGHWAY, EcoHighwayConfig, GymConfigError, make_config, updated_config
from roadload.gym.ecodrive import DriveScales
from roadload.gym.traffic_ego import ego_road_profile
from roadload.presets import get_preset
from roadload.envs.simulator import LateralValidityWarning, Simulator

ROAD_LENGTH = 10_000.0
"""Length of highway-env's straight road network [m] (its default)."""
EGO_START = 100.0
"""Minimum x of the ego at reset [m]; the simulator's s = x - x0."""

HIGHWAY_SCALE = {"v": 30.0, "a": 3.0, "grade": 0.05, "gap": 100.0, "dx": 100.0, "dy": 4.0 * 3, "dv": 30.0}


def highway_observation_layout(config: EcoHighwayConfig) -> list[tuple[str, str, float]]:
    """(name, SI unit, scale) of each observation entry, in order (the observation is value / scale,
    clipped to [-5, 5])."""
    rows = [("v", "m/s", HIGHWAY_SCALE["v"]), ("a", "m/s^2", HIGHWAY_SCALE["a"]),
            ("grade", "rad", HIGHWAY_SCALE["grade"]), ("lane", "1 (0 = leftmost, 1 = rightmost)", 1.0),
            ("front_gap", "m (capped at 200)", HIGHWAY_SCALE["gap"]),
            ("front_closing_speed", "m/s", HIGHWAY_SCALE["dv"])]
    for k in range(config.observed_vehicles):
        rows += [(f"veh{k}_presence", "1", 1.0), (f"veh{k}_dx", "m", HIGHWAY_SCALE["dx"]),
                 (f"veh{k}_dy", "m", HIGHWAY_SCALE["dy"]), (f"veh{k}_dvx", "m/s", HIGHWAY_SCALE["dv"]),
                 (f"veh{k}_dvy", "m/s", HIGHWAY_SCALE["dv"])]
    return rows


# --------------------------------------------------------------------------------------------- the ego vehicle
class RoadloadEgoVehicle(ControlledVehicle):
    """highway-env vehicle with roadload's longitudinal dynamics: lateral motion by highway-env's steering
    controller (lane keeping, lane changes), speed by the simulator ``plant`` under the wheel-force command."""

    # attributes of highway-env's (untyped) ControlledVehicle that this class reads and writes
    target_lane_index: tuple[str, str, int]
    speed: float

    def __init__(self, road: Road, position, heading: float = 0.0, speed: float = 0.0,
                 target_lane_index=None, target_speed=None, route=None) -> None:
        super().__init__(road, position, heading, speed, target_lane_index, target_speed, route)
        self.plant: Simulator | None = None
        self.scales: DriveScales | None = None
        self.n_substeps = 10
        self.command = 0.0
        self.log: dict[str, float] = {}
        self.reset_log()

    def reset_log(self) -> None:
        self.log = {"energy": 0.0, "distance": 0.0, "mechanical": 0.0, "jerk": 0.0, "headway": 0.0,
                    "lane_change": 0.0, "time": 0.0}

    def request(self, command: float, lane_change: int) -> None:
        """Hold the normalised force command; lane_change -1 left, +1 right, 0 keep (highway-env semantics)."""
        self.command = command
        if lane_change:
            _from, _to, _id = self.target_lane_index
            n = len(self.road.network.graph[_from][_to])
            target = (_from, _to, int(np.clip(_id + lane_change, 0, n - 1)))
            if target != self.target_lane_index and self.road.network.get_lane(target).is_reachable_from(
                    self.position):
                self.target_lane_index = target
                self.log["lane_change"] += 1.0

    def act(self, action: dict | str | None = None) -> None:
        """Steering from highway-env's lane controller; the longitudinal command is held (see request)."""
        self.follow_road()
        steering = float(np.clip(self.steering_control(self.target_lane_index), -self.MAX_STEERING_ANGLE,
                                 self.MAX_STEERING_ANGLE))
        Vehicle.act(self, {"steering": steering, "acceleration": 0.0})

    def clip_actions(self) -> None:
        if self.crashed:
            super().clip_actions()
            return
        self.action["steering"] = float(self.action["steering"])
        self.action["acceleration"] = float(self.action["acceleration"])

    def step(self, dt: float) -> None:
        if self.crashed or self.plant is None or self.scales is None:  # no roadload plant: highway-env kinematics
            super().step(dt)
            return
        v0 = self.speed
        a0 = self.plant.state.a
        s0 = self.plant.state.s
        v_plant0 = self.plant.state.v
        climb0 = float(self.plant.vehicle_state.climbing_work)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", LateralValidityWarning)
            st = self.plant.step(self.scales.wheel_force(self.command, v0), self.n_substeps)
        self.action["acceleration"] = (st.v - v0) / dt  # highway-env integrates the speed to st.v
        super().step(dt)
        self.speed = float(st.v)
        jerk = float(st.a - a0) / dt
        log = self.log
        log["energy"] += float(st.source_energy)
        log["distance"] += float(st.s - s0)
        x = self.plant.vehicle_state
        log["mechanical"] += (0.5 * float(x.mass) * (float(st.v) ** 2 - float(v_plant0) ** 2)
                              + float(x.climbing_work) - climb0)
        log["jerk"] += jerk * jerk * dt
        log["time"] += dt
        h_min = self._headway_min
        if h_min > 0:
            gap, _ = self.front_gap()
            headway = gap / max(self.speed, 1.0)
            if headway < h_min:
                log["headway"] += (h_min - headway) * dt

    _headway_min = 1.0

    def front_gap(self) -> tuple[float, float]:
        """Bumper-to-bumper gap [m] to the vehicle ahead in the ego's lane (inf if none) and its closing speed
        [m/s] (positive = approaching)."""
        front, _ = self.road.neighbour_vehicles(self, self.lane_index)
        if front is None:
            return math.inf, 0.0
        gap = self.lane_distance_to(front) - 0.5 * (self.LENGTH + front.LENGTH)
        return float(gap), float(self.speed - front.speed * math.cos(front.heading - self.heading))


# --------------------------------------------------------------------------------------------- action / observation
class _EgoAction(ActionType):
    def __init__(self, env: "EcoHighwayEnv", mode: str) -> None:
        super().__init__(env)
        self.mode = mode

    def space(self) -> spaces.Space:
        force = spaces.Box(-1.0, 1.0, shape=(1,), dtype=np.float32)
        if self.mode == "off":
            return force
        if self.mode == "dict":
            return spaces.Dict({"force": force, "lane_change": spaces.Discrete(3)})
        return spaces.Box(-1.0, 1.0, shape=(2,), dtype=np.float32)

    @property
    def vehicle_class(self):
        return RoadloadEgoVehicle

    def decode(self, action) -> tuple[float, int]:
        """(normalised force in [-1, 1], lane change -1 / 0 / +1)."""
        if self.mode == "dict":
            u = float(np.asarray(action["force"]).reshape(-1)[0])
            lane = {0: 0, 1: -1, 2: 1}[int(action["lane_change"])]
        else:
            a = np.asarray(action, dtype=float).reshape(-1)
            u = float(a[0])
            lane = 0
            if self.mode == "box":
                lane = -1 if a[1] < -1 / 3 else (1 if a[1] > 1 / 3 else 0)
        if not math.isfinite(u):
            raise ValueError(f"action: force command must be finite, got {action!r}")
        return float(np.clip(u, -1.0, 1.0)), lane

    def act(self, action) -> None:
        u, lane = self.decode(action)
        self.controlled_vehicle.request(u, lane)


class _EgoObservation(ObservationType):
    def __init__(self, env: "EcoHighwayEnv", layout: list[tuple[str, str, float]], n_vehicles: int) -> None:
        super().__init__(env)
        self.scale = np.array([row[2] for row in layout])
        self.n_vehicles = n_vehicles

    def space(self) -> spaces.Space:
        return spaces.Box(-5.0, 5.0, shape=(self.scale.size,), dtype=np.float32)

    def observe(self) -> np.ndarray:
        env = self.env
        ego: RoadloadEgoVehicle = env.vehicle
        x = np.zeros(self.scale.size)
        if ego is None or env.road is None or ego.plant is None:
            return x.astype(np.float32)
        st = ego.plant.state
        lanes = len(env.road.network.all_side_lanes(ego.lane_index))
        gap, closing = ego.front_gap()
        x[:6] = (ego.speed, st.a, st.grade, ego.lane_index[2] / max(lanes - 1, 1), min(gap, 200.0), closing)
        others = env.road.close_objects_to(ego, env.PERCEPTION_DISTANCE, count=self.n_vehicles, see_behind=True,
                                           sort=True, vehicles_only=True)
        c, s = math.cos(ego.heading), math.sin(ego.heading)
        rot = np.array([[c, s], [-s, c]])
        for k, other in enumerate(others):
            dp = rot @ (other.position - ego.position)
            dv = rot @ (other.velocity - ego.velocity)
            x[6 + 5 * k:11 + 5 * k] = (1.0, dp[0], dp[1], dv[0], dv[1])
        return np.clip(x / self.scale, -5.0, 5.0).astype(np.float32)


# --------------------------------------------------------------------------------------------- the env
class EcoHighwayEnv(AbstractEnv):
    """Highway traffic with a roadload ego (module docstring). ``gymnasium.make("roadload/EcoHighway-v0",
    config={...})`` or keyword overrides; ``reset(options={...})`` may change vehicle, road, effects, traffic and
    reward fields (not lane_changes / observed_vehicles, which shape the spaces)."""

    metadata: dict[str, Any] = {"render_modes": ["rgb_array"], "render_fps": 10}

    def __init__(self, config: EcoHighwayConfig | dict | None = None, render_mode: str | None = None,
                 **overrides: Any) -> None:
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise GymConfigError(f"render_mode: must be one of {self.metadata['render_modes']}, got {render_mode!r}")
        if render_mode == "rgb_array" and os.environ.get("SDL_VIDEODRIVER", "") in ("", "dummy"):
            # headless: SDL's 'offscreen' driver needs no display; highway-env draws nothing at all under 'dummy'
            # (its EnvViewer disables itself), so 'dummy' would give black frames
            os.environ["SDL_VIDEODRIVER"] = "offscreen"
        self.typed_config: EcoHighwayConfig = make_config(EcoHighwayConfig, config, **overrides)
        self.layout = highway_observation_layout(self.typed_config)
        self._plant_key: tuple[Any, ...] | None = None
        self._plant: Simulator | None = None
        self._road_seed = 0
        # validate vehicle / road / effects now (a bad one fails here, not mid-episode)
        self._build_plant(self.typed_config, road_seed=self.typed_config.road_seed or 0, sim_seed=0)
        super().__init__(config=self._highway_dict(self.typed_config), render_mode=render_mode)

    # ------------------------------------------------------------------ configuration
    @staticmethod
    def _highway_dict(cfg: EcoHighwayConfig) -> dict[str, Any]:
        return {"lanes_count": cfg.lanes_count, "vehicles_count": cfg.vehicles_count,
                "vehicles_density": cfg.vehicles_density, "duration": cfg.duration, "ego_spacing": 2,
                "controlled_vehicles": 1, "initial_lane_id": None,
                "simulation_frequency": cfg.simulation_frequency, "policy_frequency": cfg.policy_frequency,
                "screen_width": cfg.screen_width, "screen_height": cfg.screen_height,
                "other_vehicles_type": "highway_env.vehicle.behavior.IDMVehicle"}

    def define_spaces(self) -> None:
        cfg = self.typed_config
        self.action_type = _EgoAction(self, cfg.lane_changes)
        self.observation_type = _EgoObservation(self, self.layout, cfg.observed_vehicles)
        self.action_space = self.action_type.space()
        self.observation_space = self.observation_type.space()

    def _build_plant(self, cfg: EcoHighwayConfig, road_seed: int, sim_seed: int) -> None:
        length = min(ROAD_LENGTH, max(2000.0, cfg.duration * 60.0 + 500.0))
        key = (cfg.vehicle, cfg.road, road_seed, repr(cfg.effects), cfg.speed_limit, length)
        if key != self._plant_key:
            try:
                spec = get_preset(cfg.vehicle)
                # highway-env's road is straight and flat across: keep the grade, no curvature / bank
                road = ego_road_profile(cfg.road, length, road_seed, cfg.speed_limit, curvature=False)
                self._plant = Simulator(spec, road, cfg.effects, None, sim_seed, initial_speed=cfg.initial_speed)
            except GymConfigError:
                raise
            except ValueError as exc:
                raise GymConfigError(f"cannot build the ego vehicle: {exc}") from exc
            self._scales = DriveScales.from_spec(spec)
            self._plant_key = key
        self._road_seed = road_seed
        self.simulator.reset(seed=sim_seed, initial_speed=cfg.initial_speed)

    # ------------------------------------------------------------------ episode
    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        if options:
            new = updated_config(self.typed_config, options, SPACE_FIELDS_HIGHWAY)
            self.typed_config = new
            self.configure(self._highway_dict(new))
        return super().reset(seed=seed)

    def _reset(self) -> None:
        cfg = self.typed_config
        road_seed = cfg.road_seed if cfg.road_seed is not None else self._draw_road_seed()
        self._build_plant(cfg, road_seed, int(self.np_random.integers(0, 2 ** 31 - 1)))
        self.road = Road(network=RoadNetwork.straight_road_network(cfg.lanes_count, speed_limit=cfg.speed_limit,
                                                                   length=ROAD_LENGTH),
                         np_random=self.np_random, record_history=False)
        other_type = class_from_path(self.config["other_vehicles_type"])
        n_others = near_split(cfg.vehicles_count, num_bins=1)[0] if cfg.vehicles_count else 0
        spawn = Vehicle.create_random(self.road, speed=cfg.initial_speed, spacing=self.config["ego_spacing"])
        ego = RoadloadEgoVehicle(self.road, spawn.position, spawn.heading, cfg.initial_speed)
        if ego.position[0] < EGO_START:
            ego.position = ego.position + np.array([EGO_START, 0.0])
            ego.on_state_update()
        ego.plant = self._plant
        ego.scales = self._scales
        ego.n_substeps = cfg.n_substeps
        ego._headway_min = cfg.min_time_headway
        self.controlled_vehicles = [ego]
        self.road.vehicles.append(ego)
        for _ in range(n_others):
            other = other_type.create_random(self.road, spacing=1 / cfg.vehicles_density)
            other.randomize_behavior()
            other.check_collisions = False  # as highway-fast-v0: only the ego's collisions are checked
            self.road.vehicles.append(other)

    def _draw_road_seed(self) -> int:
        """The road seed of an episode without a fixed one: uniform in [0, 10000) from the env's RNG."""
        return int(self.np_random.integers(0, 10_000))

    def step(self, action):
        action = validate_action(action, self.action_space)
        self.vehicle.reset_log()
        return super().step(action)

    def _rewards(self, action) -> dict[str, float]:
        log = self.vehicle.log
        return {"progress": log["distance"], "energy": log["energy"], "mechanical": log["mechanical"],
                "collision": float(self.vehicle.crashed),
                "headway": log["headway"], "jerk": log["jerk"], "lane_change": log["lane_change"]}

    def _reward(self, action) -> float:
        w = self.typed_config.reward
        t = self._rewards(action)
        return float(w.scale * (w.progress * t["progress"] - w.energy * t["energy"]
                                + w.mechanical_energy * t["mechanical"] - w.collision * t["collision"]
                                - w.headway * t["headway"] - w.jerk * t["jerk"] - w.lane_change * t["lane_change"]))

    def _is_terminated(self) -> bool:
        return bool(self.vehicle.crashed)

    def _is_truncated(self) -> bool:
        return bool(self.time >= self.typed_config.duration or self.simulator.state.done)

    def _info(self, obs, action=None) -> dict[str, Any]:
        ego = self.vehicle
        st = self.simulator.state
        gap, _ = ego.front_gap()
        return {"speed": float(ego.speed), "crashed": bool(ego.crashed), "lane": int(ego.lane_index[2]),
                "s": float(st.s), "t": float(st.t), "source_energy_total": float(st.source_energy_total),
                "front_gap": gap, "road_seed": self._road_seed, "terms": self._rewards(action)}

    @property
    def simulator(self) -> Simulator:
        """The ego's simulator (true parameters, energy ledger, to_trip())."""
        if self._plant is None:
            raise GymConfigError("EcoHighway: no ego simulator (building it failed; see the error it raised)")
        return self._plant
