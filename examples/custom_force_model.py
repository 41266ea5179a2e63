"""Plug a force model of your own into the eco-driving MPC and compare it with the built-in ones.

    python examples/custom_force_model.py --quick     # 1.5 km of road (< 1 min)
    python examples/custom_force_model.py             # 6 km

The custom model here is the nominal car's coast-down coefficients (M0) with a mass error you choose
(``--mass-error`` [kg]); any object with ``reset()``, ``observe(sample)``, ``parameters() -> RoadLoadParameters``
and ``describe()`` works (the ``ForceModel`` protocol of roadload.controllers.force_model). Prints energy
[kWh], trip time [s], violations and fallbacks per force model, on the same road and seed.
"""

from __future__ import annotations

import argparse

import pandas as pd

from roadload.controllers import (DriveContext, FixedForceModel, RoadLoadParameters, MpcController,
                                  MpcControllerSettings, MpcSettings, OracleForceModel)
from roadload.controllers.closed_loop import run_closed_loop
from roadload.controllers.sim_plant import SimulatorPlant
from roadload.controllers.vehicle_models import abc_parameters, energy_model_from_spec
from roadload.road_profiles import hilly
from roadload.tables import markdown_table


class MassErrorModel:
    """The coast-down coefficients of the nominal car with a wrong mass m_V + mass_error [kg]."""

    name = "mass_error"

    def __init__(self, base: RoadLoadParameters, mass_error: float) -> None:
        self.params = base.with_(mass=base.mass + mass_error)

    def reset(self) -> None:
        pass

    def observe(self, sample: dict[str, float]) -> None:
        pass  # an online model would update its parameters from the latest CAN sample here

    def parameters(self) -> RoadLoadParameters:
        return self.params

    def describe(self) -> dict:
        return {"force_model": self.name, **self.params.to_dict()}


def drive_with(force_model_factory, road, vehicle: str, seed: int, time_weight: float) -> dict:
    """One closed-loop MPC drive with the force model ``force_model_factory(plant)``."""
    plant = SimulatorPlant(vehicle, road, seed=seed, dt=0.1)
    ctx = DriveContext(road=road, energy=energy_model_from_spec(vehicle), force_model=force_model_factory(plant),
                       dt=0.1)
    controller = MpcController(MpcControllerSettings(mpc=MpcSettings(time_weight=time_weight)))
    return run_closed_loop(controller, plant, ctx).metrics


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="1.5 km of road instead of 6 km")
    parser.add_argument("--vehicle", default="bmw_i3", help="vehicle preset")
    parser.add_argument("--mass-error", type=float, default=300.0, help="mass error of the custom model [kg]")
    parser.add_argument("--time-weight", type=float, default=3000.0, help="MPC lambda [J/s]")
    parser.add_argument("--seed", type=int, default=1)
    args = parser.parse_args()
    road = hilly(seed=args.seed, length=1500.0 if args.quick else 6000.0)
    abc = abc_parameters(args.vehicle)
    models = {
        "oracle (true parameters)": lambda plant: OracleForceModel(plant.true_parameters),
        "abc (coast-down, M0)": lambda plant: FixedForceModel(abc),
        f"custom: abc with {args.mass_error:+.0f} kg": lambda plant: MassErrorModel(abc, args.mass_error),
    }
    rows = []
    for label, factory in models.items():
        m = drive_with(factory, road, args.vehicle, args.seed, args.time_weight)
        rows.append({"force model": label, "arrived": m["arrived"], "energy kWh": m["energy_kWh"],
                     "time s": m["trip_time"], "violations": m["speed_violations"], "fallbacks": m["fallbacks"]})
    print(markdown_table(pd.DataFrame(rows), floatfmt=".3f"))


if __name__ == "__main__":
    main()
