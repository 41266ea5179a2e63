"""The selftest's harness: the scoring rule against the nothing-withheld reference, the confusion table and its
Markdown, what counts as an out-of-catalog effect left unexplained and localised, and (slow) the preset on the
independent world."""

from __future__ import annotations

from types import SimpleNamespace

import pytest
from roadload.experiments.sim2real.harness import (NONE_WORLD, OUTSIDE_WORLD, WorldCaseResult, WorldRun,
                                                   confusion_markdown, found_against_reference, outside_localised)
from roadload.experiments.sim2real.selftest import run_world

NONE, OUTSIDE = NONE_WORLD, OUTSIDE_WORLD


def _diag(identified, bins=(), present=False, importance=()):
    return SimpleNamespace(identified=list(identified),
                           unexplained=SimpleNamespace(departing_bins=[SimpleNamespace(**b) for b in bins],
                                                       present=present,
                                                       reference_importance=[SimpleNamespace(column=c)
                                                                             for c in importance]))


def test_out_of_catalog_effect_must_stay_unexplained_and_localised():
    band = [{"regime": "speed", "bin": "50-70 km/h"}]
    assert outside_localised(_diag([], band, True)) == (True, "speed: 50-70 km/h")
    assert not outside_localised(_diag(["latency"], band, True))[0]                 # something accepted
    assert not outside_localised(_diag([], [{"regime": "speed", "bin": "30-50 km/h"}], True))[0]   # elsewhere
    assert outside_localised(_diag([], (), True, importance=("speed",)))[0]          # the reference's speed
    assert not outside_localised(_diag([], band, False))[0]                           # nothing left unexplained


def test_confusion_table_and_markdown():
    rows = [WorldCaseResult("w", 0, "payload", "mass_offset", ["mass_offset"], True, True, 1, 1, 0, [], "", 0),
            WorldCaseResult("w", 1, "payload", "drag_area", ["drag_area"], False, False, 1, 1, 0, [], "", 0),
            WorldCaseResult("w", 0, NONE, "unexplained", [], True, True, 1, 1, 0, [], "", 0),
            WorldCaseResult("w", 1, "drag_area", "error: boom", [], False, False, 1, 1, 0, [], "", 0, "boom")]
    run = WorldRun("w", "matched", rows)
    m = run.confusion()
    assert m.loc["payload", "mass_offset"] == 1 and m.loc["payload", "drag_area"] == 1
    assert m.loc["drag_area", "error"] == 1
    s = run.summary()
    assert (s["top1_correct"], s["catalog_cases"], s["false_acceptances_none"], s["errors"]) == (1, 3, 0, 1)
    md = confusion_markdown(run.confusion(seed=0)).splitlines()
    assert md[0] == "| withheld \\ identified | mass_offset | unexplained |"
    assert md[2] == "| payload | 1 |  |"


# ------------------------------------------------------- scoring rule: found beyond the nothing-withheld reference
def _case(withheld, fits, seed=0, stands_for=()):
    r = WorldCaseResult("w", seed, withheld, "-", [], False, False, 1.0, 1.0, 0.0, [], "", 1.0)
    r.fits, r.stands_for = fits, tuple(stands_for)
    return r


def _base(value, se, size=100.0, significant=True, name="delta m_V", min_size=15.0):
    return {"source": "base", "significant": significant, "size_rms": size, "min_size": min_size,
            "parameters": {name: (value, se)}}


def _effect(**params):
    return {"source": "effect", "significant": True, "parameters": params}


def test_found_against_reference_separates_the_withheld_effect_from_the_preset_mismatch():
    aux0 = _base(-1670.0, 130.0, size=1670.0, name="delta P_aux", min_size=100.0)
    ref = _case(NONE, {"base:mass_offset": _base(457.0, 2.0, size=500.0), "base:auxiliary_power": aux0,
                       "auxiliary_power": _effect(**{"delta P_aux": (-1670.0, 130.0)})})
    payload = _case("payload", {"base:mass_offset": _base(665.0, 2.0, size=700.0)}, stands_for=["mass_offset"])
    assert found_against_reference(payload, ref)                     # +208 kg beyond the preset's own +457 kg
    same = _case("payload", {"base:mass_offset": _base(459.0, 2.0, size=500.0)}, stands_for=["mass_offset"])
    assert not found_against_reference(same, ref)                    # only the preset's mismatch (0.7 sigma)
    small = _case("payload", {"base:mass_offset": _base(470.0, 2.0, size=500.0)}, stands_for=["mass_offset"])
    assert not found_against_reference(small, ref)                   # 4.6 sigma, but 14 N < 15 N of contribution
    assert found_against_reference(small, None)                      # no reference: a significant departure counts
    aux = _case("auxiliary_load", {"auxiliary_power": _effect(**{"delta P_aux": (-1700.0, 140.0)})},
                stands_for=["auxiliary_power"])
    assert not found_against_reference(aux, ref)                     # accepted in the reference too, not moved
    aux.fits["auxiliary_power"]["parameters"]["delta P_aux"] = (-170.0, 140.0)
    assert found_against_reference(aux, ref)                         # moved by 1500 W
    # the load cancels the preset's own mismatch: nothing accepted, but the energy base moved by 1500 W
    cancel = _case("auxiliary_load", {"base:auxiliary_power": _base(-170.0, 130.0, size=170.0, name="delta P_aux",
                                                                    significant=False, min_size=100.0)},
                   stands_for=["auxiliary_power"])
    assert found_against_reference(cancel, ref)
    # matched sim: the reference accepts nothing, an accepted candidate standing for the effect is found
    wind = _case("wind", {"wind_world": _effect(w=(6.0, 0.5))}, stands_for=["wind", "wind_world"])
    assert found_against_reference(wind, _case(NONE, {}))
    assert not found_against_reference(_case("wind", {}, stands_for=["wind_world"]), _case(NONE, {}))
    run = WorldRun("w", "preset", [ref, payload, same, _case(OUTSIDE, {})])
    s = run.summary()
    assert (s["found"], s["catalog_cases"], s["found_cases"]) == (1, 2, 2)


@pytest.mark.slow
def test_preset_on_the_independent_world_names_nothing_and_finds_bias_and_torque_gain_in_the_base(tmp_path):
    """The shipped bmw_i3 against the independent world (3 x 300 s, seed 0), base first and refitted jointly with
    every candidate: nothing withheld accepts nothing on either side (before: the preset's battery mismatch was
    accepted as ``auxiliary_power`` ≈ -1.7 kW on every drive); an accelerometer bias of 0.1 m/s² comes out of the
    logged elevation (0.10 ± 0.002 over 3 x 900 s); the inverter's +5 % torque gain moves the energy base's
    drive-torque signal gain g by ≈ +0.05."""
    run = run_world("independent", seeds=(0,), effects=("none", "accel_bias", "torque_scale"), duration=300.0,
                    vehicle="bmw_i3", work=str(tmp_path))
    res = {r.withheld: r for r in run.results}
    assert not res["none"].accepted and not res["none"].error
    bias = res["accel_bias"].fits["base:accel_bias"]["parameters"]["accelerometer bias b"]
    bias0 = res["none"].fits["base:accel_bias"]["parameters"]["accelerometer bias b"]
    assert bias[0] == pytest.approx(0.1, abs=0.015) and abs(bias0[0]) < 0.015
    gain = res["torque_scale"].fits["base:torque_scale"]["parameters"]["drive-torque signal gain error g"]
    gain0 = res["none"].fits["base:torque_scale"]["parameters"]["drive-torque signal gain error g"]
    assert gain[0] - gain0[0] == pytest.approx(0.05, abs=0.02)
    run.score()
    assert res["accel_bias"].found and res["torque_scale"].found
