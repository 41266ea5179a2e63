"""Equal-time matching by a joint local fit, paired CIs and the force-model spec parser."""

import numpy as np
import pytest

from roadload.experiments.controller_comparison import (PairedTask, _mean_ci, other_metric_results, paired_summary,
                                                        parse_force_model, refit_results)
from roadload.experiments.time_matching import fit_energy_at_time


def _curve(t, level, t_ref=400.0, slope=-2.0, curv=15.0):
    x = t / t_ref - 1.0
    return level * (1.0 + slope * x + curv * x * x)


def test_joint_fit_recovers_levels_on_a_convex_curve():
    t_ref = 400.0
    runs = {"oracle": [(t, _curve(t, 1.0e6)) for t in (385.0, 398.0, 409.0, 420.0)],
            "abc": [(t, _curve(t, 1.01e6)) for t in (388.0, 401.0, 414.0)]}
    fit = fit_energy_at_time(runs, t_ref)
    # the shared shape is additive in E/E_ref: exact for equal levels, 1e-4 for levels 1 % apart
    assert fit.energy["oracle"] == pytest.approx(1.0e6, rel=2e-4)
    assert fit.energy["abc"] == pytest.approx(1.01e6, rel=2e-4)
    assert fit.energy["abc"] / fit.energy["oracle"] == pytest.approx(1.01, abs=2e-4)
    assert fit.slope == pytest.approx(-2.0, rel=0.02)
    assert fit.spanned == {"oracle": True, "abc": True}
    assert fit.nearest["abc"] == pytest.approx(1.0 / 400.0)
    # linear interpolation between the wide bracket (385, 420) overstates the energy on the convex curve
    e1, e2 = _curve(385.0, 1.0e6), _curve(420.0, 1.0e6)
    linear = e1 + (t_ref - 385.0) * (e2 - e1) / 35.0
    assert linear > 1.0e6 * 1.001


def test_fit_ignores_runs_outside_the_window_and_reports_missing_models():
    runs = {"oracle": [(400.0, 1.0), (404.0, 0.99), (396.0, 1.01)], "far": [(600.0, 0.5)]}
    fit = fit_energy_at_time(runs, 400.0)
    assert np.isnan(fit.energy["far"]) and fit.spanned["far"] is False
    assert fit.n_points == 3
    with pytest.raises(ValueError, match="target_time"):
        fit_energy_at_time(runs, 0.0)


def test_mean_ci_matches_student_t():
    mean, se, lo, hi = _mean_ci(np.array([1.0, 2.0, 3.0, 4.0]))
    assert mean == pytest.approx(2.5)
    assert se == pytest.approx(np.std([1, 2, 3, 4], ddof=1) / 2.0)
    assert hi - mean == pytest.approx(3.182446 * se, rel=1e-5)  # t_{0.975, 3}
    assert lo == pytest.approx(2 * mean - hi)


def test_paired_summary_flags_unresolved_differences():
    def result(seed, abc, online):
        return {"task": {"case": "car", "road": "hilly", "condition": "nominal", "seed": seed},
                "energy_at_tref_J": {"oracle": 100.0, "abc": abc, "online": online}, "cruise_energy_J": 110.0,
                "nearest_time_error": {"oracle": 0.001, "abc": 0.002, "online": 0.003}, "fit_residual_std": 0.003}
    rs = [result(0, 102.0, 100.2), result(1, 103.0, 99.7), result(2, 102.5, 100.1)]
    s = paired_summary(rs).set_index("force_model")
    assert s.loc["abc", "vs_oracle_pct"] == pytest.approx(2.5)
    assert bool(s.loc["abc", "resolved"]) is True
    assert bool(s.loc["online", "resolved"]) is False  # mean 0 within its CI
    assert s.loc["oracle", "vs_cruise_pct"] == pytest.approx(100 * (100 / 110 - 1))


def test_parse_force_model():
    assert parse_force_model("abc") == ("abc", None)
    assert parse_force_model("wrong:mass=0.2,grade_bias=-0.005") == ("wrong", {"mass": 0.2, "grade_bias": -0.005})
    with pytest.raises(ValueError, match="force model"):
        parse_force_model("magic")


def test_paired_task_rejects_unknown_metric_and_negative_warmup():
    with pytest.raises(ValueError, match="metric"):
        PairedTask("car", "hilly", 0, metric="energy")
    with pytest.raises(ValueError, match="warmup"):
        PairedTask("truck_40t", "long_grades", 0, warmup=-1.0)


def test_other_metric_results_swap_in_the_same_runs_second_evaluation():
    r = {"task": {"case": "car", "road": "hilly", "condition": "nominal", "seed": 0, "metric": "net"},
         "t_ref": 120.0, "energy_at_tref_J": {"oracle": 100.0, "abc": 101.0}, "cruise_energy_J": 110.0,
         "nearest_time_error": {"oracle": 0.0, "abc": 0.001}, "fit_residual_std": 0.001,
         "other_metric": {"metric": "raw", "t_ref": 120.1, "energy_at_tref_J": {"oracle": 100.0, "abc": 99.0},
                          "cruise_energy_J": 105.0, "fit_residual_std": 0.004,
                          "nearest_time_error": {"oracle": 0.0, "abc": 0.002}}}
    rs = [r, {**r, "task": {**r["task"], "seed": 1}}]
    net = paired_summary(rs).set_index("force_model")
    raw = paired_summary(other_metric_results(rs)).set_index("force_model")
    assert net.loc["abc", "vs_oracle_pct"] == pytest.approx(1.0) and net.loc["abc", "metric"] == "net"
    assert raw.loc["abc", "vs_oracle_pct"] == pytest.approx(-1.0) and raw.loc["abc", "metric"] == "raw"
    assert raw.loc["oracle", "fit_residual_std_pct"] == pytest.approx(0.4)


def test_refit_results_recovers_levels_and_books_the_kinetic_energy_offset():
    # one seed: oracle and abc on the convex curve (abc 0.5 % above), cruise control on its own curve; the net
    # metric adds cruise control's kinetic-energy offset (a constant) to every run, the raw one does not
    t_ref, off = 120.0, 2.0e5

    def run(model, t, level, **kw):
        e = _curve(t, level, t_ref=t_ref)
        return {"force_model": model, "trip_time": t, "energy_J": e + 7.0, "segment_time": t,
                "energy_net_J": e - off, **kw}

    runs = [run("cruise", t, 1.1e6) for t in (120.0, 123.0, 117.0, 126.0, 114.0)]
    runs += [run("oracle", t, 1.0e6, time_weight=1.0) for t in (113.0, 118.0, 120.0, 124.0)]
    runs += [run("abc", t, 1.005e6, time_weight=1.0) for t in (115.0, 119.5, 125.0)]
    r = {"task": {"case": "car", "road": "hilly", "condition": "nominal", "seed": 0, "tol": 0.002},
         "runs": runs, "kinetic_energy_offset_J": off}
    net = refit_results([r], "net", window=0.06)[0]
    assert net["t_ref"] == pytest.approx(120.0)
    assert net["energy_at_tref_J"]["oracle"] == pytest.approx(1.0e6, rel=2e-4)
    assert net["energy_at_tref_J"]["abc"] / net["energy_at_tref_J"]["oracle"] == pytest.approx(1.005, abs=2e-4)
    assert net["cruise_energy_J"] == pytest.approx(1.1e6, rel=2e-4)
    raw = refit_results([r], "raw", window=0.06)[0]
    assert raw["energy_at_tref_J"]["oracle"] == pytest.approx(1.0e6 + 7.0, rel=2e-4)
    with pytest.raises(ValueError, match="metric"):
        refit_results([r], "kwh")


def test_fastsim_cross_check_gaps_are_the_differences_of_the_savings():
    from roadload.experiments.controller_comparison import fastsim_per_seed

    def result(seed, rl, eff, fs):  # (cruise, MPC) energies [J] in the three scorings
        return {"task": {"seed": seed}, "cruise_energy_J": rl[0], "energy_at_tref_J": {"oracle": rl[1]},
                "fastsim_efficiency_cruise_energy_J": eff[0],
                "fastsim_efficiency_energy_at_tref_J": {"oracle": eff[1]},
                "fastsim_cruise_energy_J": fs[0], "fastsim_energy_at_tref_J": {"oracle": fs[1]}}

    results = [result(0, (1000, 900), (1000, 860), (950, 810)), result(1, (2000, 1900), (2000, 1880),
                                                                      (1900, 1790)), result(2, (1500, 1400),
                                                                                            (1500, 1350), (1400, 1240))]
    per_seed, totals = fastsim_per_seed(results)
    assert per_seed["roadload_saving_pct"].tolist() == pytest.approx([-10.0, -5.0, -100 / 15])
    t = totals.set_index("what")["pct"]
    assert t["roadload saving"] == pytest.approx(-300 / 4500 * 100)  # fleet total: sum dE / sum E_cruise
    assert t["fastsim_efficiency saving"] == pytest.approx(-410 / 4500 * 100)
    assert t["fastsim saving"] == pytest.approx(-410 / 4250 * 100)
    assert t["fastsim - roadload [pp]"] == pytest.approx(t["fastsim saving"] - t["roadload saving"])
    assert t["fastsim - fastsim_efficiency [pp]"] == pytest.approx(t["fastsim saving"]
                                                                   - t["fastsim_efficiency saving"])
    assert "fastsim_efficiency_driving saving" not in t  # runs stored before that scoring: left out, not failed
    for r, driving in zip(results, ((1000, 880), (2000, 1890), (1500, 1380))):
        r["fastsim_efficiency_driving_cruise_energy_J"] = driving[0]
        r["fastsim_efficiency_driving_energy_at_tref_J"] = {"oracle": driving[1]}
    t = fastsim_per_seed(results)[1].set_index("what")["pct"]
    assert t["fastsim_efficiency_driving saving"] == pytest.approx(-350 / 4500 * 100)
    # the efficiency gap splits into driving and regenerating / coasting exactly
    assert (t["fastsim_efficiency_driving - roadload [pp]"] + t["fastsim_efficiency - fastsim_efficiency_driving [pp]"]
            == pytest.approx(t["fastsim_efficiency - roadload [pp]"]))
