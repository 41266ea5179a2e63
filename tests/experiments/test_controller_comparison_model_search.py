"""run_paired_task's per-model lambda search: a force model whose runs at lambda* x factors
all land on the other side of T_ref (the online truck MPC on the slow cruise branch at every lambda) gets extra runs
that bracket T_ref, instead of the seed being dropped from the table. Closed loop replaced by an analytic one."""

from types import SimpleNamespace

import numpy as np
import pandas as pd
import pytest

import roadload.experiments.controller_comparison as cc

JUMP = 1.5e5  # [J/s] the online model reaches the fast branch only above this lambda


def _oracle_time(lam: float) -> float:
    return 168.0 + 5.0 * (1e5 / lam - 1.0)


def _energy(t: float, model: str) -> float:
    extra = {"oracle": 0.0, "abc": 0.004, "online": 0.002}[model]
    return (56e6 - 0.5e6 * (t - 168.0)) * (1.0 + extra)


def _fake_drive(vehicle, road, effects=None, seed=0, settings=None):
    st = settings
    if st.controller == "cruise":
        t = 170.0 * 0.95 / st.cruise.fraction
        e = 56.3e6 - 0.4e6 * (t - 170.0)
    else:
        t = _oracle_time(st.time_weight)
        if st.force_model == "online" and st.time_weight < JUMP:
            t += 30.0  # the slow branch
        elif st.force_model != "oracle":
            t += 0.1
        e = _energy(t, st.force_model)
    m = {"segment_time": t, "energy_net_J": e, "trip_time": t + 100.0, "energy_J": e + 30e6, "segment_energy_J": e,
         "arrival_speed": 23.0, "segment_start_speed": 23.0, "kinetic_energy_change_J": 0.0, "speed_violations": 0,
         "ctl_time_weight_median": float("nan"), "ctl_multistart_switches": 0, "solve_time_median": 0.005,
         "fallbacks": 0, "online": {}}
    log = pd.DataFrame({"s": np.linspace(0.0, road.length, 50), "t": np.linspace(0.0, t + 100.0, 50)})
    return SimpleNamespace(metrics=m, log=log), None


@pytest.mark.parametrize("extra_runs", [0, 3])
def test_a_model_on_the_other_branch_is_searched_not_dropped(monkeypatch, extra_runs):
    monkeypatch.setattr(cc, "drive", _fake_drive)
    task = cc.PairedTask("truck_15t", "long_grades", 0, warmup=2000.0, model_search_runs=extra_runs)
    out = cc.run_paired_task(task)
    t_ref = out["t_ref"]
    online = [r for r in out["runs"] if r["force_model"] == "online"]
    if extra_runs == 0:
        assert len(online) == 3 and all(r["segment_time"] > 1.1 * t_ref for r in online)
        assert not np.isfinite(out["energy_at_tref_J"]["online"])  # the seed would be dropped
        return
    assert 4 <= len(online) <= 3 + extra_runs
    assert any(r["time_weight"] > JUMP for r in online)  # the search reached the fast branch
    # T_ref lies in the online model's branch gap: the nearest run is on the fast branch, inside the fit window
    assert out["nearest_time_error"]["online"] < 0.03
    truth = _energy(t_ref, "online") / _energy(t_ref, "oracle") - 1.0
    got = out["energy_at_tref_J"]["online"] / out["energy_at_tref_J"]["oracle"] - 1.0
    assert got == pytest.approx(truth, abs=5e-4)
    # abc reached T_ref at lambda* x factors: no extra runs
    assert len([r for r in out["runs"] if r["force_model"] == "abc"]) == 3


def test_model_search_settings_are_checked():
    with pytest.raises(ValueError, match="model_search_runs"):
        cc.PairedTask("truck_15t", "long_grades", 0, model_search_runs=-1)
    with pytest.raises(ValueError, match="model_reach"):
        cc.PairedTask("truck_15t", "long_grades", 0, model_reach=float("nan"))


def test_headline_cli_passes_the_gear_command_and_model_search_to_every_task(monkeypatch, tmp_path):
    """`roadload benchmark headline --mpc-gear --model-search-runs N` reaches every PairedTask (the sweep itself is
    replaced: only the plumbing is under test), and a negative N is refused with the option's name."""
    from typer.testing import CliRunner

    from roadload.experiments.cli import _load, app

    _load()
    import roadload.experiments.headline as headline  # the command imports run_paired from here when it runs

    seen = []

    def fake_run_paired(tasks, out, **kw):  # no runs: the command then stops with "every task failed"
        seen.extend(tasks)
        return pd.DataFrame(), []

    monkeypatch.setattr(headline, "run_paired", fake_run_paired)
    runner = CliRunner()
    args = ["benchmark", "headline", "--vehicles", "truck_15t", "--seeds", "2", "--out", str(tmp_path)]
    res = runner.invoke(app, [*args, "--mpc-gear", "--model-search-runs", "2"])
    assert len(seen) == 2, res.output
    assert all(t.gear_command and t.model_search_runs == 2 for t in seen)
    seen.clear()
    runner.invoke(app, args)
    assert seen and not any(t.gear_command or t.model_search_runs for t in seen)  # off by default
    bad = runner.invoke(app, [*args, "--model-search-runs", "-1"])
    assert bad.exit_code != 0 and "--model-search-runs" in bad.output
