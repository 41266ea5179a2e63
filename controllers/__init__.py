"""Eco-driving control: spatial MPC (CasADi; IPOPT and OSQP paths), force models (abc / online / oracle),
baselines (PI cruise control, the simulator's human-like driver) and the closed-loop comparison."""

from roadload.road_load import RoadLoadParameters
from .base import Command, ControllerBase, ControllerError, DriveContext, Observation
from .cruise import CruiseController, CruiseSettings
from .energy import SourceEnergyModel
from .force_model import FixedForceModel, ForceModel, ForceModelError, OracleForceModel
from .mpc import MpcError, MpcSettings
from .mpc_controller import MpcController, MpcControllerSettings

__all__ = ["Command", "ControllerBase", "ControllerError", "DriveContext", "Observation", "CruiseController",
           "CruiseSettings", "SourceEnergyModel", "FixedForceModel", "ForceModel", "ForceModelError",
           "RoadLoadParameters", "OracleForceModel", "MpcError", "MpcSettings", "MpcController",
           "MpcControllerSettings"]
