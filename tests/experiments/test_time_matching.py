"""The joint local fit must not book a force model's effect as an energy-time trade-off:
when no model's runs spread in time, the shared slope is not identified."""

import math

import pytest

from roadload.experiments.time_matching import fit_energy_at_time


def test_fit_without_time_spread_does_not_extrapolate_between_models():
    # 40 t seed 5 of the schedule run: every target gave the same time per model (no time authority)
    runs = {"oracle": [(230.56, 123.89e6)] * 3, "abc": [(235.72, 125.91e6)] * 3, "online": [(226.70, 126.57e6)] * 3}
    fit = fit_energy_at_time(runs, 226.8)
    # old behaviour: a slope from the between-model differences put the oracle at 102.6 MJ (its runs: 123.9 MJ)
    assert math.isnan(fit.energy["oracle"]) and math.isnan(fit.energy["abc"])
    assert fit.energy["online"] == pytest.approx(126.57e6)  # within 0.2 % of the target: its own runs
    assert math.isnan(fit.residual_std)


def test_fit_with_time_spread_recovers_a_known_curve_and_model_offsets():
    def energy(t, offset):
        x = t / 200.0 - 1.0
        return 100e6 * (1.0 + offset - 2.0 * x + 5.0 * x * x)

    runs = {"oracle": [(t, energy(t, 0.0)) for t in (196.0, 200.5, 204.0)],
            "abc": [(t, energy(t, 0.01)) for t in (198.0, 201.0, 205.0)]}
    fit = fit_energy_at_time(runs, 200.0)
    assert fit.energy["oracle"] == pytest.approx(100e6, rel=1e-9)
    assert fit.energy["abc"] == pytest.approx(101e6, rel=1e-9)
    assert fit.slope == pytest.approx(-2.0, rel=0.01)  # relative to the median energy of the runs
