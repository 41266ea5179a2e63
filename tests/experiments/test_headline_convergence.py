"""The truck convergence table: estimate error by distance from the online estimate's history."""

import pytest

from roadload.experiments.headline import convergence_table


def _run(seed, mass_estimates):
    s = [500.0, 1500.0, 3000.0, 5000.0]
    return {"case": "truck_40t", "seed": seed, "length_m": 6000.0, "s": s,
            "truth": {"m_V": 40000.0, "rho_a/2 A_V c_x": 3.4, "m_V f_r0": 220.0},
            "estimate": {"m_V": mass_estimates, "rho_a/2 A_V c_x": [3.4] * 4, "m_V f_r0": [110.0] * 4}}


def test_convergence_table_takes_the_last_update_before_each_distance():
    runs = [_run(0, [27500.0, 38000.0, 40400.0, 40000.0]), _run(1, [27500.0, 42000.0, 39600.0, 40000.0])]
    t = convergence_table(runs, at=(2000.0, 4000.0, 8000.0)).set_index(["parameter", "distance_km"])
    # at 2 km the last updates are at 1.5 km: -5 % and +5 % -> median 0, largest |error| 5 %
    assert t.loc[("m_V", 2.0), "error_median_pct"] == pytest.approx(0.0, abs=1e-9)
    assert t.loc[("m_V", 2.0), "error_abs_max_pct"] == pytest.approx(5.0)
    assert t.loc[("m_V", 4.0), "error_abs_max_pct"] == pytest.approx(1.0)
    assert t.loc[("m_V f_r0", 4.0), "error_median_pct"] == pytest.approx(-50.0)
    assert ("m_V", 8.0) not in t.index  # beyond the road length
