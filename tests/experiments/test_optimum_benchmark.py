"""The optimum benchmark's bookkeeping, the force-model specs of the paired comparison and the FASTSim check."""

import json
from dataclasses import replace

import numpy as np
import pandas as pd
import pytest

from roadload.estimators.change import GUST_ROBUST
from roadload.experiments.controller_comparison import force_model_settings
from roadload.experiments.optimum_benchmark import (BOUND_KIND, OptimumBenchmarkError, OptimumTask, _settings,
                                                    _stale_bound, breakdown_tasks, dp_table, episode_cost_summary,
                                                    online_columns, pace_and_drive, reference_controller, stored_task,
                                                    summarise, summary_markdown, write_tables)
from roadload.road_profiles import RoadProfile


def test_excess_summary_is_a_fleet_total_with_its_ci():
    rows = pd.DataFrame({"vehicle": "car", "road": "hilly", "controller": "cruise", "seed": range(4),
                         "arrived": True, "energy_J": [110.0, 220.0, 330.0, 440.0],
                         "optimum_energy_J": [100.0, 200.0, 300.0, 400.0], "time_s": 100.0,
                         "optimum_time_s": 100.1, "excess_pct": 10.0})
    left_out = rows.iloc[:1].assign(seed=9, optimum_energy_J=np.nan)  # no optimum (too fast): counted, not used
    s = summarise(pd.concat([rows, left_out], ignore_index=True)).iloc[0]
    assert s.seeds == 4 and s.runs_left_out == 1
    assert s.excess_pct == pytest.approx(10.0)  # 100 mean(E - E_opt) / mean(E_opt)
    assert s.excess_ci95_lo < 10.0 < s.excess_ci95_hi
    assert s.optimum_time_error_pct_max == pytest.approx(0.1)


def test_excess_keeps_its_sign_where_the_optimum_regenerates_more_than_it_draws():
    # a slow drive down a short hilly road: the optimum's net energy -104 kJ, the run's -100 kJ (4 kJ more)
    rows = pd.DataFrame({"vehicle": "car", "road": "hilly_short", "controller": "ppo", "seed": range(2),
                         "arrived": True, "energy_J": [-90e3, -110e3], "optimum_energy_J": [-94e3, -114e3],
                         "time_s": 120.0, "optimum_time_s": 120.0, "excess_pct": 4.0})
    s = summarise(rows).iloc[0]
    assert s.excess_pct == pytest.approx(100 * 4e3 / 104e3)  # above the optimum: positive


def test_controllers_are_compared_with_the_oracle_mpc_at_equal_time_through_their_optima():
    """Each run against the optimum at its own time: an online run 2 % slower than the oracle run uses 20 J less,
    but its optimum is 30 J lower: 10 J further above its optimum, it is 10 J (1 %) worse at equal time."""
    oracle = pd.DataFrame({"vehicle": "car", "road": "hilly", "condition": "headwind_6ms",
                           "controller": "mpc:oracle", "seed": range(4), "arrived": True,
                           "energy_J": [1000.0, 1010.0, 990.0, 1000.0],
                           "optimum_energy_J": [990.0, 1000.0, 980.0, 990.0],
                           "time_s": 100.0, "optimum_time_s": 100.0, "excess_pct": 1.0})
    online = oracle.assign(controller="mpc:online_wind", time_s=102.0, optimum_time_s=102.0,
                           energy_J=oracle.energy_J - 30.0 + [9.0, 10.0, 11.0, 10.0],
                           optimum_energy_J=oracle.optimum_energy_J - 30.0)
    s = summarise(pd.concat([oracle, online], ignore_index=True)).set_index("controller")
    assert s.loc["mpc:online_wind", "vs_mpc:oracle_pct"] == pytest.approx(1.0)
    assert s.loc["mpc:online_wind", "vs_mpc:oracle_ci95_lo"] > 0.8
    assert s.loc["mpc:oracle", "vs_mpc:oracle_pct"] == 0.0
    md = summary_markdown(s.reset_index())
    assert "headwind_6ms" in md and "| reference |" in md and "+1.00 % [" in md


def test_without_the_oracle_mpc_the_tables_compare_with_the_oracle_mpc_variant_that_ran(tmp_path):
    """A truck run of the speed-band cruise and the plant-map MPC only: the equal-time column and the pace/drive
    split are against 'mpc:oracle:plant_map', not 'n/a' against an absent 'mpc:oracle'. The band's runs lie 20 J
    further above their optima than the MPC's on 1000 J: +2 % at equal time."""
    assert reference_controller(["cruise_band", "mpc:oracle:plant_map", "mpc:oracle"]) == "mpc:oracle"
    assert reference_controller(["cruise_band", "mpc:oracle:plant_map"]) == "mpc:oracle:plant_map"
    assert reference_controller(["cruise", "human"]) == "mpc:oracle"
    mpc = pd.DataFrame({"vehicle": "truck_40t", "road": "long_grades", "condition": "nominal",
                        "controller": "mpc:oracle:plant_map", "seed": range(3), "arrived": True,
                        "energy_J": 1000.0, "optimum_energy_J": 990.0, "time_s": 200.0, "optimum_time_s": 200.0,
                        "excess_pct": 1.0})
    band = mpc.assign(controller="cruise_band", time_s=180.0, optimum_time_s=180.0, optimum_energy_J=1100.0,
                      energy_J=1100.0 + 10.0 + np.array([19.0, 20.0, 21.0]))
    results = [{"task": {"case": "truck_40t", "time_weight": 4000.0},
                "rows": pd.concat([band, mpc], ignore_index=True).to_dict("records")}]
    _, summary = write_tables(results, [], tmp_path)
    s = summary.set_index("controller")
    assert s.loc["cruise_band", "vs_mpc:oracle:plant_map_pct"] == pytest.approx(2.0)
    md = (tmp_path / "summary.md").read_text()
    assert "vs mpc:oracle:plant_map at equal time" in md and "| reference |" in md and "+2.00 % [" in md
    assert "n/a" not in md and "drive vs mpc:oracle:plant_map" in md


def test_an_online_runs_row_carries_its_estimate_at_the_segment_start_and_end():
    """The last update before the warm-up's end is the estimate the measured segment starts with."""
    online = {"change_alarms": 2, "clipped": 0, "wind_speed": 5.8, "wind_direction": 3.1,
              "estimate": {"m_V f_r0": 12.9, "m_V": 1460.0},
              "history": {"parameters": ["m_V f_r0", "m_V"], "t": [10.0, 20.0, 30.0], "s": [400.0, 1490.0, 1700.0],
                          "x": [[14.0, 1500.0], [13.1, 1470.0], [12.9, 1460.0]]}}
    row = online_columns(online, warmup=1500.0)
    assert json.loads(row["online_estimate_start"]) == {"m_V f_r0": 13.1, "m_V": 1470.0}
    assert json.loads(row["online_estimate_end"]) == online["estimate"]
    assert row["online_alarms"] == 2 and row["online_wind_speed"] == 5.8
    assert online_columns(None, 1500.0) == {}
    assert json.loads(online_columns({**online, "history": {}}, 1500.0)["online_estimate_start"]) == {}


def test_cost_against_the_mpc_splits_into_pace_along_the_optimum_and_drive_above_it():
    """A policy 40 s slower than the MPC: its optimum saves 200 kJ for the 40 s, which lambda = 3000 J/s prices at
    120 kJ (pace: -80 kJ), and it drives 50 kJ further above its optimum (drive: +50 kJ): cost -30 kJ. Over the
    MPC's cost of 1000 + 3 x 120 = 1360 kJ: pace -5.88 %, drive +3.68 %, together -2.21 %."""
    mpc = pd.DataFrame({"vehicle": "car", "road": "route", "condition": "nominal", "controller": "mpc:oracle",
                        "seed": range(3), "arrived": True, "time_s": 120.0, "energy_J": [1.0e6, 1.01e6, 0.99e6],
                        "optimum_energy_J": [0.99e6, 1.0e6, 0.98e6]})
    ppo = mpc.assign(controller="ppo", time_s=160.0, optimum_energy_J=mpc.optimum_energy_J - 2.0e5,
                     energy_J=mpc.energy_J - 2.0e5 + [4.9e4, 5.0e4, 5.1e4])
    r = pace_and_drive(pd.concat([mpc, ppo], ignore_index=True), {"car": 3000.0}).iloc[0]
    assert r.controller == "ppo" and r.seeds == 3 and r.time_s == 160.0 and r.time_s_ref == 120.0
    assert r.pace_pct == pytest.approx(-100 * 80.0 / 1360.0) and r.pace_1sigma_pct == pytest.approx(0.0)
    assert r.drive_pct == pytest.approx(100 * 50.0 / 1360.0)
    assert r.cost_pct == pytest.approx(r.pace_pct + r.drive_pct)
    assert r.drive_ci95_lo < r.drive_pct < r.drive_ci95_hi


def test_dp_check_difference_keeps_its_sign_on_a_route_that_regenerates():
    """A downhill route's net energy is negative: the DP 1226 J above the NLP is +1.26 % of |E_NLP|, not -1.26 %
    (the stored value / reference - 1 of older results is recomputed)."""
    results = [{"dp": {"nlp_energy_J": -97610.7, "dp_energy_J": -96384.8, "dp_vs_nlp_pct": -1.256,
                       "speed_step": 0.05}},
               {"dp": {"nlp_energy_J": 1157199.8, "dp_energy_J": 1158062.4, "dp_vs_nlp_pct": 0.075,
                       "speed_step": 0.05}}]
    dp = dp_table(results)
    assert dp["dp_minus_nlp_J"].tolist() == pytest.approx([1225.9, 862.6])
    assert dp["dp_vs_nlp_pct"].tolist() == pytest.approx([1.2559, 0.07454], rel=1e-3)
    summary = pd.DataFrame(columns=["vehicle", "road", "controller", "seeds", "time_s_mean", "energy_kJ_mean",
                                    "optimum_kJ_mean", "excess_pct", "excess_1sigma_pct", "excess_ci95_lo",
                                    "excess_ci95_hi"])
    assert "+0.075 … +1.256 % of |E_NLP|, +863 … +1226 J" in summary_markdown(summary, dp)


def test_episode_cost_is_compared_per_seed():
    rows = pd.DataFrame({"controller": ["ppo"] * 3 + ["mpc"] * 3, "seed": [1, 2, 3] * 2,
                         "cost_J": [100.0, 200.0, 300.0, 104.0, 208.0, 312.0], "energy_J": 1.0, "time_s": 1.0,
                         "arrival_speed": 1.0})
    s = episode_cost_summary(rows, "ppo").set_index("controller")
    assert s.loc["mpc", "vs_pct"] == pytest.approx(4.0) and s.loc["ppo", "vs_pct"] == 0.0


def test_force_model_specs_of_the_paired_comparison():
    assert force_model_settings("abc") == {"force_model": "abc", "wrong_model": None}
    s = force_model_settings("online@RRLM+forgetting=0.995+cusum")
    assert s["estimator"] == "RRLM" and s["estimator_settings"]["forgetting"] == 0.995
    assert s["change_detection"] is GUST_ROBUST and s["change_detection"].window > 1  # the test on block means
    assert force_model_settings("online_wind@SGMKF")["force_model"] == "online_wind"
    with pytest.raises(ValueError, match="online models only"):
        force_model_settings("oracle@RRLM")
    with pytest.raises(ValueError, match="key=value"):
        force_model_settings("online@RRLM+fast")


def test_bad_benchmark_tasks_are_refused_with_the_reason():
    with pytest.raises(OptimumBenchmarkError, match="unknown"):
        OptimumTask("car", "hilly", 0, controllers=("mpc:magic",))
    with pytest.raises(OptimumBenchmarkError, match="car only"):
        OptimumTask("truck_40t", "long_grades", 0, controllers=("ppo",))
    with pytest.raises(OptimumBenchmarkError, match="vehicle case"):
        OptimumTask("bus", "hilly", 0)
    with pytest.raises(OptimumBenchmarkError, match="key=value"):
        OptimumTask("car", "hilly", 0, controllers=("mpc:online_wind@RRLM+fast",))
    with pytest.raises(OptimumBenchmarkError, match="truck_optimum 'exact'.*bound"):
        OptimumTask("truck_40t", "long_grades", 0, truck_optimum="exact")


def test_a_stored_task_comes_back_equal_and_its_bound_is_stale_when_the_grid_changed():
    task = OptimumTask("truck_40t", "long_grades", 3, controllers=("cruise_band", "mpc:oracle"), warmup=2000.0,
                       mpc=(("n_nodes", 80),))
    stored = json.loads(json.dumps({"task": task.__dict__}, default=float))
    assert stored_task(stored["task"]) == task
    rows = [{"arrived": True, "optimum_kind": BOUND_KIND}, {"arrived": False}]
    assert not _stale_bound(task, {"rows": rows})
    assert _stale_bound(task, {"rows": [{**rows[0], "optimum_kind": "plant-fuel bound"}]})
    assert not _stale_bound(replace(task, truck_optimum="tracked"), {"rows": [{"arrived": True}]})


def test_the_truck_breakdown_varies_one_lever_of_the_plant_map_mpc_on_the_seeds_asked_for():
    tasks = breakdown_tasks({"truck_40t": ["long_grades"]}, [8, 5], controller="mpc:oracle:plant_map",
                            variants=["base", "route end in the horizon", "|lambda x0.5", "re-plan 0.2 s"],
                            warmup=2000.0)
    assert [(t.seed, t.label) for t in tasks] == [
        (s, lab) for s in (8, 5) for lab in ("", "|route end in the horizon", "|lambda x0.5", "|re-plan 0.2 s")]
    base, route_end, slow, replan = (_settings(t, "mpc:oracle:plant_map") for t in tasks[:4])
    # every variant keeps the plant-map fuel model and its gear request; only its own lever moves
    assert {s.mpc.fuel_model for s in (base, route_end, slow, replan)} == {"plant_map"}
    assert base.gear_command and base.mpc.horizon == 2000.0 and base.time_weight == 160_000.0
    assert route_end.mpc.horizon == 4000.0 and route_end.mpc.horizon_to_route_end
    assert replace(route_end.mpc, n_nodes=40, horizon_to_route_end=False) == base.mpc
    assert slow.time_weight == 80_000.0 and slow.mpc == base.mpc
    assert replan.replan_period == 0.2 and base.replan_period == 1.0 and replan.mpc == base.mpc
    near = _settings(breakdown_tasks({"truck_40t": ["long_grades"]}, [0], controller="mpc:oracle:plant_map",
                                     variants=["near grid 8 x 12.5 m"])[0], "mpc:oracle:plant_map").mpc
    assert near.horizon == base.mpc.horizon and near.grid_lengths()[0] == 12.5
    assert len(breakdown_tasks({"car": ["hilly"]}, 2)) == 2 * 12  # a count of seeds from 0, every car variant
    with pytest.raises(OptimumBenchmarkError, match="unknown.*'|horizon 9 km'.*choose from"):
        breakdown_tasks({"truck_40t": ["long_grades"]}, [0], variants=["horizon 9 km"])
    with pytest.raises(OptimumBenchmarkError, match="oracle MPC.*'cruise'"):
        breakdown_tasks({"truck_40t": ["long_grades"]}, [0], controller="cruise")


def test_an_online_mpc_takes_its_estimator_options_after_the_at():
    task = OptimumTask("car", "hilly", 0, controllers=("mpc:online_wind@RRLM+forgetting=0.995+cusum",))
    s = _settings(task, task.controllers[0])
    assert s.controller == "mpc" and s.force_model == "online_wind"
    assert s.change_detection is not None and s.estimator_settings["forgetting"] == 0.995
    assert _settings(task, "mpc:oracle").change_detection is None


def test_fastsim_energy_of_a_trace_rises_with_the_grade():
    pytest.importorskip("fastsim")
    from roadload.experiments.fastsim_check import fastsim_energy

    def road(grade):
        s = np.arange(0.0, 1001.0, 5.0)
        z = np.zeros_like(s)
        return RoadProfile("straight", s, np.full_like(s, grade), z, z, np.full_like(s, 30.0))

    t = np.arange(0.0, 50.01, 0.1)
    v = np.full_like(t, 20.0)
    flat, climb = (fastsim_energy(t, 20.0 * t, v, road(g))["energy_J"] for g in (0.0, 0.02))
    # the climb's extra energy is about m g sin(theta) v t / eta at the drive's efficiency (0.6 .. 1)
    extra = 1400.0 * 9.81 * np.sin(0.02) * 1000.0
    assert 1.0 < (climb - flat) / extra < 1.7
    assert flat > 0
