"""One owner per default and per check: the estimators' defaults are written once, every settings class validates
through pydantic with errors naming the setting, the value and the range, and no compiled kernel takes a long
argument list."""

import ast
from pathlib import Path

import numpy as np
import pytest

from roadload import estimators as E
from roadload.estimators import config as C
from roadload.experiments.benchmarks.kernel_signatures import kernel_signatures
from roadload.estimators.pipeline import PipelineError, PipelineSettings, smoother_design

ESTIMATORS_DIR = Path(E.__file__).parent


def _numeric_literals(value: float) -> list[str]:
    """Modules of estimators/ (and line numbers) where ``value`` is written as a number in the code."""
    hits = []
    for path in sorted(ESTIMATORS_DIR.glob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Constant) and type(node.value) in (int, float) and node.value == value:
                hits.append(f"{path.name}:{node.lineno}")
    return hits


@pytest.mark.parametrize("value, owner", [(0.999, "config.py"), (1e6, "config.py"), (1.483, "influence.py"),
                                          (1.57, "evaluation.py")])
def test_each_default_is_written_once_in_its_owner(value, owner):
    hits = _numeric_literals(value)
    assert len(hits) == 1 and hits[0].startswith(owner + ":"), hits


def test_every_estimator_takes_its_defaults_from_the_one_owner():
    assert E.make_config("RLS", n_params=2).forgetting == C.FORGETTING
    assert E.make_config("KF", n_params=2, process_noise=1e-4).output_noise == C.OUTPUT_NOISE
    assert E.make_config("RIV", n_params=2).instrument_delay == C.INSTRUMENT_DELAY
    rgtls = E.make_estimator("RGTLS", n_params=2)
    assert rgtls.forgetting == rgtls.nce_forgetting == C.FORGETTING
    assert np.array_equal(rgtls.p0, C.INITIAL_COVARIANCE * np.eye(3))
    assert rgtls.blowup == C.BLOWUP_RATIO * C.INITIAL_COVARIANCE
    # section 5.5's table lists the library's defaults, it does not restate them
    defaults = C.estimator_defaults()
    for model in ("M3", "M4"):
        for name, settings in E.chapter5_settings(model).items():
            for key in set(settings) & {"p0", "forgetting", "output_noise", "instrument_delay", "scale0",
                                        "quantile0", "scale_forgetting", "learn_rate"}:
                assert settings[key] == defaults[key], (model, name, key)
            if "kappa" in settings:
                assert settings["kappa"] == E.CATALOG[name].parts["kappa"]
    # the PKS: one design class holds the defaults for the smoother, the bank and RGTLS's noise estimator
    assert E.PolynomialKalmanSmoother().design == E.PKSDesign() == rgtls.settings.pks
    assert E.pks_bank(np.zeros(50)).design == E.PKSDesign()


def test_the_pipeline_smoother_keeps_its_memory_in_seconds_at_other_rates():
    settings = PipelineSettings()
    at_100 = smoother_design(settings, 100.0)
    assert (at_100.window_left, at_100.window_right, at_100.n_params, at_100.forgetting) == (50, 50, 3, 0.98)
    at_50 = smoother_design(settings, 50.0)
    assert (at_50.window_left, at_50.window_right) == (25, 25)
    assert at_50.forgetting ** 50 == pytest.approx(0.98 ** 100, rel=1e-12)   # same memory over 1 s


@pytest.mark.parametrize("make, message", [
    (lambda: E.RecursiveGTLS(3, forgetting=1.5), r"forgetting must lie in \(0.0, 1.0\] \[1\], got 1.5"),
    (lambda: E.RecursiveGTLS(3, nce_forgetting=-0.1), r"nce_forgetting must lie in \[0.0, 1.0\] \[1\], got -0.1"),
    (lambda: E.RecursiveGTLS(3, blowup_ratio=1.0), r"blowup_ratio must lie in \(1.0, inf\) \[1\], got 1.0"),
    (lambda: E.RecursiveGTLS(0), r"n_params must be an integer >= 1, got 0"),
    (lambda: E.RecursiveGTLS(3, nce="yes"), r"nce must be true or false, got 'yes'"),
    (lambda: E.RecursiveGTLS(3, window=3), r"unknown setting\(s\) \['window'\]"),
    (lambda: E.RecursiveGTLS(3, p0=[1.0, 2.0]), r"p0: expected 4 diagonal entries, got 2"),
    (lambda: E.RecursiveGTLS(3, noise_covariance=-1.0), r"noise_covariance \(P̌\) must be positive semi-definite"),
    (lambda: E.RecursiveGTLS(3, x0=[1.0, np.nan, 0.0]), r"x0 must be 3 finite numbers"),
    (lambda: E.RecursiveGTLS(3, pks={"window_right": -2}),
     r"pks: window_right must be an integer >= 0 \[samples\], got -2"),
    (lambda: E.PKSDesign(n_params=9), r"n_params must be an integer in \[1, 8\], got 9"),
    (lambda: E.PKSDesign(forgetting=0.0), r"forgetting must lie in \(0.0, 1.0\] \[1\], got 0.0"),
    (lambda: E.PKSDesign(p0=float("inf")), r"p0 must lie in \(0.0, inf\) \[1\], got inf"),
    (lambda: E.PolynomialKalmanSmoother(window_left=2.5), r"window_left must be an integer >= 0 \[samples\]"),
    (lambda: E.pks_bank(np.zeros(10), order=2, n_params=4), r"order 2 and n_params 4 disagree"),
])
def test_rgtls_and_pks_settings_errors_name_the_setting_value_and_range(make, message):
    with pytest.raises(E.EstimatorConfigError, match=message):
        make()


def test_numpy_scalars_are_accepted_by_every_settings_class():
    est = E.RecursiveGTLS(np.int64(2), nce=np.True_, pks=dict(n_params=np.int64(3), window_left=np.int32(5)))
    assert (est.n_params, est.nce, est.settings.pks.n_params, est.settings.pks.window_left) == (2, True, 3, 5)


def test_no_compiled_kernel_takes_more_than_twelve_parameters():
    kernels = kernel_signatures([ESTIMATORS_DIR], ESTIMATORS_DIR.parent)
    sizes = {f"{Path(k.path).name}:{k.name}": k.parameters for k in kernels}
    assert {"kernel.py:run_record", "rgtls.py:rgtls_record", "kernel.py:store_sample",
            "influence.py:weight_scalar"} <= set(sizes)
    assert sizes["kernel.py:run_record"] == 6 and sizes["rgtls.py:rgtls_record"] == 7
    too_long = {k: v for k, v in sizes.items() if v > 12}
    assert not too_long, too_long


@pytest.mark.parametrize("settings, message", [
    (dict(min_speed=-1.0), r"min_speed must lie in \[0.0, inf\) \[m/s\], got -1.0"),
    (dict(estimation_rate=0), r"estimation_rate must lie in \(0.0, inf\) \[Hz\], got 0"),
    (dict(warmup="2"), r"warmup must be a number \[s\], got '2'"),
    (dict(gradient="gps"), r"gradient: .*'accelerometer', 'grade_channel' or 'auto', got 'gps'"),
    (dict(smoother={"window": 50, "orders": 2}), r"smoother: unknown setting\(s\) \['orders'\]"),
    (dict(smoother={"window": 50, "forgetting": 1.2}), r"smoother: forgetting must lie in \(0.0, 1.0\] \[1\], got 1.2"),
])
def test_pipeline_settings_errors_name_the_setting_value_and_range(settings, message):
    with pytest.raises(PipelineError, match=message):
        PipelineSettings(**settings)
    assert PipelineSettings().drive_torque_floor == -np.inf   # -inf (off) stays allowed
