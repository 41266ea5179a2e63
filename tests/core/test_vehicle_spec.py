"""Vehicle specs are pydantic dataclasses: bounds and units declared in the fields, cross-field physics in model
validators, every error one line naming the field, the bound and the unit."""

import dataclasses

import pytest
from pydantic.dataclasses import is_pydantic_dataclass

from roadload.presets import PRESETS, get_preset
from roadload.vehicle import (BodySpec, ChannelSensorSpec, Curve, DrivetrainSpec, SensorSpec, VehicleSpec,
                              VehicleSpecError, parse_spec)


def test_every_part_is_a_pydantic_dataclass():
    spec = get_preset("gt_rwd")
    for part in (spec, spec.body, spec.aero, spec.tires, spec.drivetrain, spec.brakes, spec.steering, spec.sensors,
                 spec.drivetrain.differential_loss):
        assert is_pydantic_dataclass(type(part)), type(part).__name__


@pytest.mark.parametrize("name", PRESETS)
def test_presets_pass_and_round_trip(name):
    spec = get_preset(name)
    again = VehicleSpec.from_dict(spec.to_dict())
    assert again == spec and again.mass == spec.mass


def test_direct_construction_is_validated_and_names_the_field():
    with pytest.raises(VehicleSpecError, match=r"^BodySpec\.mass: must be > 0 \[kg\], got -5"):
        BodySpec(mass=-5, wheelbase=2.8, cg_to_front_axle=1.3)
    with pytest.raises(VehicleSpecError, match=r"^ChannelSensorSpec\.noise_std: must lie in \[0, inf\)"):
        ChannelSensorSpec(-1.0)  # positional, like the presets
    with pytest.raises(VehicleSpecError, match=r"^Curve\.y: length 1 differs from x length 2"):
        Curve([0.0, 1.0], [1.0])
    body = BodySpec(1500, 2.8, 1.3)  # ints are JSON numbers: kept as floats
    assert body.mass == 1500.0 and isinstance(body.mass, float)


def test_dataclasses_replace_revalidates():
    body = get_preset("gt_rwd").body
    assert dataclasses.replace(body, mass=1800.0).mass == 1800.0
    with pytest.raises(VehicleSpecError, match=r"BodySpec\.mass: 10000000\.0 kg is outside the plausible range"):
        dataclasses.replace(body, mass=1e7)


def test_cross_field_checks_name_the_limiting_field():
    d = get_preset("gt_rwd").to_dict()
    d["drivetrain"]["gear_ratios"] = [3.0, 3.5] + d["drivetrain"]["gear_ratios"][2:]
    with pytest.raises(VehicleSpecError, match=r"vehicle\.drivetrain\.gear_ratios: must be strictly decreasing "
                                               r"from first gear up, got 3\.0 then 3\.5 at gears 1, 2"):
        VehicleSpec.from_dict(d)
    d = get_preset("bmw_i3").to_dict()
    d["drivetrain"]["motor"]["max_power"] = 2000.0   # 2 kW cannot move 1.4 t at 20 m/s
    with pytest.raises(VehicleSpecError, match=r"vehicle\.body\.mass: top speed .* below 20 m/s .*peak power 2 kW"):
        VehicleSpec.from_dict(d)
    d = get_preset("bmw_i3").to_dict()
    d["drivetrain"]["battery"] = None
    with pytest.raises(VehicleSpecError, match=r"vehicle\.drivetrain\.battery: required for kind 'bev'"):
        VehicleSpec.from_dict(d)
    d = get_preset("gt_rwd").to_dict()
    d["body"]["cg_to_front_axle"] = d["body"]["wheelbase"]
    with pytest.raises(VehicleSpecError, match=r"vehicle\.body\.cg_to_front_axle: must be < wheelbase"):
        VehicleSpec.from_dict(d)


def test_strings_and_bools_are_not_numbers():
    d = get_preset("gt_rwd").to_dict()
    d["body"]["mass"] = "1500"
    with pytest.raises(VehicleSpecError, match=r"vehicle\.body\.mass: expected a number \[kg\], got '1500'"):
        VehicleSpec.from_dict(d)
    with pytest.raises(VehicleSpecError, match=r"sensors\.channels\.vehicle_speed\.enabled: expected true/false"):
        parse_spec(SensorSpec, {"channels": {"vehicle_speed": {"enabled": "yes"}}}, "sensors")


def test_validate_catches_a_spec_changed_in_place():
    spec = get_preset("gt_rwd")
    spec.drivetrain.gear_ratios[0] = 0.1
    with pytest.raises(VehicleSpecError, match=r"vehicle\.drivetrain\.gear_ratios\[0\]: 0\.1 is outside the "
                                               r"plausible range \[0\.3, 25\]"):
        spec.validate()


def test_json_schema_carries_bounds_and_units():
    schema = DrivetrainSpec.__pydantic_validator__  # built: the schema compiles
    assert schema is not None
    from roadload.vehicle import vehicle_json_schema

    defs = vehicle_json_schema()["$defs"]
    ratio = defs["DrivetrainSpec"]["properties"]["gear_ratios"]
    assert ratio["items"]["minimum"] == 0.3 and ratio["items"]["maximum"] == 25.0 and ratio["maxItems"] == 12
    assert defs["BodySpec"]["properties"]["mass"]["exclusiveMinimum"] == 0.0
