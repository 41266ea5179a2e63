"""sim2real core on synthetic force data with a known injected effect (no simulator)."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from roadload.estimators.models import get_model
from roadload.sim2real.catalog import DEFAULT_CANDIDATES, get_candidate
from roadload.sim2real.errors import DiagnosisError
from roadload.sim2real.forcemodel import SimForceModel
from roadload.sim2real.regimes import bin_statistics, residual_analysis
from roadload.sim2real.selection import Selector, information_criteria, make_split
from roadload.sim2real.stats import (block_bootstrap_mean_difference, block_bootstrap_median, block_ids,
                                     cluster_covariance)
from roadload.units import G

MODEL = SimForceModel.from_physical("toy", 1500.0, 0.01, 0.0, 0.0, 0.6, 8e4)


def synth(extra_fn, n_trips=2, duration=500.0, noise=30.0, seed=0) -> pd.DataFrame:
    """Trips with varied speed / grade / curvature; measured force = the sim's balance + extra + noise."""
    rng = np.random.default_rng(seed)
    frames = []
    for k in range(n_trips):
        t = np.arange(0.0, duration, 0.1)
        v = 20 + 8 * np.sin(2 * np.pi * t / 300 + k) + 5 * np.sin(2 * np.pi * t / 71 + 2 * k) \
            + 2 * np.sin(2 * np.pi * t / 23 + k)
        th = 0.03 * np.sin(2 * np.pi * t / 400 + 3 * k) + 0.01 * np.sin(2 * np.pi * t / 97)
        kappa = 0.004 * np.sin(2 * np.pi * t / 50 + k)
        frames.append(pd.DataFrame({"trip": f"T{k}", "t": t, "time_since_start": t, "speed": v,
                                    "acceleration": np.gradient(v, t), "gradient_angle": th,
                                    "path_curvature": kappa, "air_density": 1.2, "gear": 1.0,
                                    "distance": np.cumsum(v) * 0.1, "heading": np.cumsum(kappa * v) * 0.1}))
    tab = pd.concat(frames, ignore_index=True)
    sim = MODEL.predict(tab)
    tab["brake_force"] = 0.0
    tab["tractive_force"] = sim + extra_fn(tab) + rng.normal(0, noise, len(tab))
    tab["sim_force"] = sim
    tab["sim_drive_force"] = sim
    tab["sim_drive_force_rate"] = np.concatenate([np.gradient(sim[tab.trip == k], 0.1) for k in pd.unique(tab.trip)])
    tab["lateral_acceleration"] = tab.speed ** 2 * tab.path_curvature
    tab["mode"] = np.where(sim > 0, "traction", "regen")
    tab["valid"] = True
    tab["residual"] = tab.tractive_force - tab.sim_force
    return tab


FAST = ("mass_offset", "torque_scale", "wind", "wind_world", "drag_area", "rolling_scale", "rolling_speed",
        "tire_warmup", "accel_bias")


def diagnose_table(tab, seed=0, candidates=FAST):
    split = make_split(tab, seed=seed, n_folds=4)
    sel = Selector(tab, tab.residual.to_numpy(), split, MODEL, robust=False, n_boot=150, seed=seed)
    ranked, skipped = sel.rank(candidates)
    steps = sel.forward(ranked)
    return sel, ranked, steps


def mass_extra(tab):
    th = tab.gradient_angle.to_numpy()
    return 120.0 * (G * np.sin(th) + tab.acceleration.to_numpy() + G * np.cos(th) * 0.01)


def test_injected_mass_offset_is_ranked_first_and_accepted_with_its_value():
    tab = synth(mass_extra)
    sel, ranked, steps = diagnose_table(tab)
    assert ranked[0].name == "mass_offset"
    assert ranked[0].parameters["delta m_V"] == pytest.approx(120.0, abs=6.0)
    assert ranked[0].delta_aic == 0.0 and ranked[0].significant
    assert steps[0].effect == "mass_offset" and steps[0].accepted
    assert [s.effect for s in steps if s.accepted] == ["mass_offset"]
    # the block standard error is honest: the estimate lies within 4 of them of the truth
    assert abs(ranked[0].parameters["delta m_V"] - 120.0) < 4 * ranked[0].std_errors["delta m_V"] + 1.0
    # the candidate's model structure went through the chapter-5 registry
    assert get_model("sim:toy+mass_offset").parameter_names[-1] == "delta m_V"


def test_injected_headwind_identified_in_world_frame():
    def wind(tab):
        h = tab.heading.to_numpy()
        return 1.2 * 0.6 * tab.speed.to_numpy() * (4.0 * np.cos(h) + 1.0 * np.sin(h))
    tab = synth(wind)
    _, ranked, steps = diagnose_table(tab)
    accepted = [s.effect for s in steps if s.accepted]
    assert accepted and accepted[0] in ("wind_world", "wind")
    top = next(r for r in ranked if r.name == "wind_world")
    assert top.parameters["wind w_x"] == pytest.approx(4.0, abs=0.3)
    assert top.parameters["wind w_y"] == pytest.approx(1.0, abs=0.3)


def test_effect_outside_the_catalog_is_not_forced_onto_a_candidate():
    tab = synth(lambda t: np.where((t.speed > 18) & (t.speed < 22), 150.0, 0.0))
    sel, ranked, steps = diagnose_table(tab)
    assert not any(s.accepted for s in steps)
    assert steps and "partial fit" in steps[0].reason


def test_all_catalog_candidates_fit_on_a_full_table():
    tab = synth(mass_extra, duration=300.0)
    _, ranked, _ = diagnose_table(tab, candidates=DEFAULT_CANDIDATES)
    names = {r.name for r in ranked}
    force_side = {n for n in DEFAULT_CANDIDATES if get_candidate(n).side == "force"}
    assert names == force_side - {"friction_brake", "brake_drag"}   # no braking in the synthetic trips
    assert ranked[0].name == "mass_offset"


def test_no_gap_means_nothing_accepted():
    tab = synth(lambda t: np.zeros(len(t)))
    _, ranked, steps = diagnose_table(tab)
    assert not any(s.accepted for s in steps)


def test_split_keeps_test_and_folds_apart():
    tab = synth(lambda t: np.zeros(len(t)), n_trips=2, duration=600)
    sp = make_split(tab, segment_length=60, test_fraction=1 / 3, n_folds=4)
    assert not np.any(sp.test & (sp.fold >= 0))
    assert set(np.unique(sp.fold[sp.train])) == {0, 1, 2, 3}
    assert 0.25 < sp.test.mean() < 0.42
    # whole segments: no segment is split between test and training
    for s in np.unique(sp.segments):
        sel = sp.segments == s
        assert sp.test[sel].all() or not sp.test[sel].any()


def test_information_criteria_match_eq_3_5b_3_6b():
    aic, bic = information_criteria(sse=200.0, m=100, o=3)
    assert aic == pytest.approx(100 * np.log(2.0) + 6)
    assert bic == pytest.approx(100 * np.log(2.0) + 3 * np.log(100))


def test_block_bootstrap_median_interval():
    rng = np.random.default_rng(1)
    blocks = np.repeat(np.arange(200), 50)
    noise = np.repeat(rng.normal(0, 1, 200), 50) + rng.normal(0, 0.2, blocks.size)   # block-correlated
    med, lo, hi, p = block_bootstrap_median(noise, blocks, rng, n_boot=300)
    assert lo < 0 < hi and p > 0.05
    med, lo, hi, p = block_bootstrap_median(noise + 0.5, blocks, rng, n_boot=300)
    assert lo > 0 and p < 0.05 and lo < med < hi
    # with correlated blocks the interval is much wider than a sample-wise one would be (honest)
    assert hi - lo > 2 * 1.57 * np.std(noise) / np.sqrt(noise.size) * 3


def test_block_bootstrap_mean_difference_and_cluster_covariance():
    rng = np.random.default_rng(2)
    n = 5000
    blocks = np.repeat(np.arange(100), 50)
    a = rng.normal(1.0, 0.1, n)
    mean, lo, hi = block_bootstrap_mean_difference(a, a - 0.3, blocks, rng)
    assert mean == pytest.approx(0.3) and lo == pytest.approx(0.3) and hi == pytest.approx(0.3)
    # cluster covariance: block-constant errors inflate the variance of a mean by the block size
    A = np.ones((n, 1))
    r = np.repeat(rng.normal(0, 1, 100), 50)
    cov = cluster_covariance(A, r, blocks)
    iid = np.var(r) / n
    assert cov[0, 0] > 20 * iid


def test_block_ids_split_by_trip_and_length():
    ids = block_ids(np.array(["a"] * 4 + ["b"] * 2), np.array([0.0, 5, 10, 25, 0, 3]), 10.0)
    assert ids.tolist() == [0, 0, 1, 2, 3, 3]
    with pytest.raises(DiagnosisError):
        block_ids(np.array(["a"]), np.array([0.0]), 0.0)


def test_regime_bins_localise_a_band_effect():
    tab = synth(lambda t: np.where((t.speed > 50 / 3.6) & (t.speed < 70 / 3.6), 200.0, 0.0), noise=20.0)
    blocks = block_ids(tab.trip.to_numpy(), tab.t.to_numpy(), 10.0)
    rt = bin_statistics(tab.residual.to_numpy(), tab, "speed", blocks, np.random.default_rng(0), min_effect=20)
    rows = {r.bin: r for r in rt.rows}
    assert rows["50-70 km/h"].departs and rows["50-70 km/h"].median == pytest.approx(200, abs=15)
    assert not rows["30-50 km/h"].departs


def test_residual_analysis_finds_a_lagged_input():
    rng = np.random.default_rng(3)
    x = rng.normal(0, 1, 4000)
    r = np.roll(x, 5) + 0.1 * rng.normal(0, 1, 4000)
    out = residual_analysis(r, {"x": x}, np.zeros(4000), max_lag=10)
    assert out["x"].lag == 5 and out["x"].max_abs > 0.9 > out["x"].bound


def test_candidate_missing_channels_are_named():
    cand = get_candidate("friction_brake")
    assert cand.missing({"brake_force": np.zeros(10)}) == ["brake_force"]
    assert get_candidate("cornering").missing({"speed": np.ones(3)}) == ["path_curvature"]
    with pytest.raises(DiagnosisError, match="unknown candidate"):
        get_candidate("nope")


def test_friction_brake_gain_sign_and_simulator_mapping():
    tab = synth(lambda t: np.zeros(len(t)), duration=400.0)
    rng = np.random.default_rng(5)
    fb = np.clip(rng.normal(0, 1500, len(tab)), 0, None) * (np.arange(len(tab)) % 200 < 40)
    tab["brake_force"] = fb
    # real pads grip 20 % more than the sim's nominal: the measured balance (drive - nominal F_B) shows +0.2 F_B
    tab["tractive_force"] = tab["tractive_force"] + 0.2 * fb
    tab["residual"] = tab.tractive_force - tab.sim_force
    _, ranked, steps = diagnose_table(tab, candidates=("friction_brake", "mass_offset", "torque_scale"))
    top = ranked[0]
    assert top.name == "friction_brake" and top.parameters["pad friction error k"] == pytest.approx(0.2, abs=0.02)
    assert top.sim_parameters == {"factor": pytest.approx(1.0 + top.parameters["pad friction error k"])}


def test_brake_drag_after_release_is_found_with_its_time_constant():
    from roadload.sim2real.table import time_since

    tab = synth(lambda t: np.zeros(len(t)), duration=600.0)
    brake = (np.arange(len(tab)) % 600) < 30                  # 3 s of braking every minute
    tab["brake_force"] = np.where(brake, 800.0, 0.0)
    tsb = np.concatenate([time_since(brake[(tab.trip == k).to_numpy()], tab.t[tab.trip == k].to_numpy())
                          for k in pd.unique(tab.trip)])
    tab["time_since_brake"] = tsb
    drag = np.where(np.isfinite(tsb), 120.0 * np.exp(-np.nan_to_num(tsb, nan=1e9) / 15.0), 0.0)
    tab["tractive_force"] = tab["tractive_force"] + drag     # the motion needs more drive force than the sim says
    tab["residual"] = tab.tractive_force - tab.sim_force
    _, ranked, steps = diagnose_table(tab, candidates=("brake_drag", "friction_brake", "mass_offset"))
    assert ranked[0].name == "brake_drag" and ranked[0].shape == 15.0
    assert ranked[0].parameters["residual brake drag F_d"] == pytest.approx(120.0, rel=0.1)
    assert steps[0].accepted
    assert np.isnan(time_since(np.array([False, True, False]), np.array([0.0, 1.0, 3.0]))[0])


def test_latency_candidate_fits_the_delay_with_its_sign():
    """A drive-force signal that arrives tau = 0.15 s late, F_meas(t) = F(t - tau), is explained by the latency
    candidate with tau = +0.15 s (not -0.15 s), and switched on in the simulator as +0.15 s of torque latency."""
    tau = 0.15
    tab = synth(lambda t: np.zeros(len(t)), noise=10.0)
    late = np.empty(len(tab))
    for k in pd.unique(tab.trip):
        rows = (tab.trip == k).to_numpy()
        t, f = tab.t[rows].to_numpy(), tab.sim_drive_force[rows].to_numpy()
        late[rows] = np.interp(t - tau, t, f)
    rng = np.random.default_rng(3)
    tab["tractive_force"] = late + rng.normal(0.0, 10.0, len(tab))
    tab["residual"] = tab.tractive_force - tab.sim_force
    _, ranked, steps = diagnose_table(tab, candidates=("latency", "mass_offset", "torque_scale"))
    top = ranked[0]
    assert top.name == "latency" and steps[0].effect == "latency" and steps[0].accepted
    assert top.parameters["latency tau"] == pytest.approx(tau, rel=0.1)
    assert top.sim_parameters == {"delta": pytest.approx(top.parameters["latency tau"])}
