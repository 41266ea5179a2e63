"""Estimator settings are declared (bounds, meaning and unit in the fields) and checked from the declaration."""

import dataclasses

import pytest

from roadload.estimators import EstimatorConfig, EstimatorConfigError
from roadload.estimators.config import _declared_hints


def test_every_numeric_scalar_setting_is_declared():
    declared = _declared_hints()
    # p0 (scalar, diagonal or matrix) is checked as a matrix, like Q and P_d
    numeric = {f.name for f in dataclasses.fields(EstimatorConfig) if f.name not in ("n_params", "p0")
               and isinstance(f.default, (int, float)) and not isinstance(f.default, bool)}
    numeric |= {"forgetting", "output_noise", "instrument_delay"}   # None by default: used only by some parts
    assert numeric <= set(declared), sorted(numeric - set(declared))
    for name, (integer, info) in declared.items():
        assert info.description and "[" in info.description, name   # meaning and unit


@pytest.mark.parametrize("settings, message", [
    (dict(forgetting=0.0), r"forgetting must lie in \(0.0, 1.0\] \[1\], got 0.0"),
    (dict(forgetting=float("nan")), r"forgetting must lie in"),
    (dict(quantile_p=1.0, robust_scale=True), r"quantile_p must lie in \(0.0, 1.0\)"),
    (dict(scale0="abc"), r"scale0 must be a number \[unit of B\], got 'abc'"),
    (dict(covariance_bound_ratio=1.0), r"covariance_bound_ratio must lie in \(1.0, inf\)"),
    (dict(scale_iterations=0), r"scale_iterations must be an integer >= 1, got 0"),
    (dict(scale_iterations=2.5), r"scale_iterations must be an integer >= 1, got 2.5"),
    (dict(covariance="kalman", process_noise=1e-4, output_noise=-1.0), r"output_noise must lie in \(0.0, inf\)"),
])
def test_out_of_range_settings_name_setting_range_and_unit(settings, message):
    with pytest.raises(EstimatorConfigError, match=message):
        EstimatorConfig(n_params=2, **settings)


def test_values_inside_the_declared_bounds_are_kept_as_numbers():
    cfg = EstimatorConfig(n_params=2, forgetting=1, scale_iterations=3, kappa=0)
    assert cfg.forgetting == 1.0 and isinstance(cfg.forgetting, float)
    assert cfg.scale_iterations == 3 and isinstance(cfg.scale_iterations, int)


def test_the_config_is_a_pydantic_dataclass_validated_on_replace():
    from pydantic.dataclasses import is_pydantic_dataclass

    assert is_pydantic_dataclass(EstimatorConfig)
    cfg = EstimatorConfig(2, forgetting=0.99)        # positional n_params, like a stdlib dataclass
    assert cfg.replace(forgetting=0.95).forgetting == 0.95
    with pytest.raises(EstimatorConfigError, match=r"forgetting must lie in \(0.0, 1.0\] \[1\], got 1.5"):
        dataclasses.replace(cfg, forgetting=1.5)


@pytest.mark.parametrize("settings, message", [
    (dict(robust_scale="yes"), r"robust_scale must be true or false, got 'yes'"),
    (dict(forgetting="0.99"), r"forgetting must be a number \[1\], got '0.99'"),
    (dict(p0=[[1.0, 2.0], [3.0, 4.0]]), r"p0 must be symmetric"),
    (dict(covariance="kalman", process_noise=[[1.0, 0.0], [0.0, -1.0]]), r"process_noise \(Q\) must be positive"),
])
def test_types_are_strict_and_matrices_keep_their_shape_and_psd_checks(settings, message):
    with pytest.raises(EstimatorConfigError, match=message):
        EstimatorConfig(n_params=2, **settings)


def test_numpy_scalars_count_as_python_numbers():
    import numpy as np

    cfg = EstimatorConfig(np.int64(3), scale_iterations=np.int64(2), robust_scale=np.True_)
    assert (cfg.n_params, cfg.scale_iterations, cfg.robust_scale) == (3, 2, True)
    assert cfg.kernel_arrays["P0"].shape == (3, 3)
