"""Change detection for recursive estimators: a two-sided CUSUM test on the prior residuals, and a covariance
reset when it fires, so that an estimator with long memory (RRLM with lambda = 0.999, section 5.5) follows a
step or a drift of the road load without the parameter noise of a short memory.

With the prior residual r_t = B_t - A_t X̂_{t-1} standardised by a recursive scale s_t (exponentially weighted
mean of |r|, times sqrt(pi/2) for a Gaussian), z_t = r_t / s_t, the cumulative sums

    g+_t = max(0, g+_{t-1} + z_t - nu),   g-_t = max(0, g-_{t-1} - z_t - nu)

grow only while the residuals keep one sign (a model that no longer fits), and the test fires when either exceeds
the threshold h. Then the covariance of the chosen parameters grows by ``reset_variance`` (the others keep
theirs), which raises the gain of the next updates the way the text's random-walk (Kalman) estimators do
continuously (section 3.7), but only after a detected change.

The estimators' P is not the parameter covariance: with the gain L = W P a / (c + W a P a^T) (c = lambda for the
forgetting family, R for the Kalman family) the covariance is sigma^2 P / c, sigma the output noise [unit of B].
So a covariance step of diag(reset_variance) [parameter units^2] is P <- P + c diag(reset_variance) / sigma^2,
with sigma the residual scale s_t of the test. Added to P unscaled (as if P were the covariance), a reset of
25 kg^2 on m_V f_r0 with sigma ~ 100 N made a P a^T thousands of times c: the next single sample's residual,
noise and all, was fitted entirely, and the rolling and drag estimates jumped by more than their own size.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np


class ChangeDetectionError(ValueError):
    """Invalid change-detection settings (the message names the field and the expected range)."""


@dataclass(frozen=True)
class ChangeDetection:
    """Settings of the CUSUM test and of the covariance reset.

    drift nu [1] and threshold h [1] of the standardised residual's cumulative sums; scale_forgetting [1]: the
    forgetting of the recursive residual scale; reset_variance: diagonal added to P when the test fires, per
    parameter name (units of the parameter squared); parameters not named keep their covariance."""

    drift: float = 0.5
    threshold: float = 12.0
    scale_forgetting: float = 0.99
    reset_variance: dict[str, float] = field(default_factory=lambda: {"m_V f_r0": 25.0, "rho_a/2 A_V c_x": 0.01})

    def __post_init__(self) -> None:
        for name in ("drift", "threshold"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise ChangeDetectionError(f"ChangeDetection.{name}: a finite number > 0 [1], got {value!r}")
        if not 0 < self.scale_forgetting < 1:
            raise ChangeDetectionError(f"ChangeDetection.scale_forgetting: in (0, 1), got {self.scale_forgetting}")
        for k, v in self.reset_variance.items():
            if not (math.isfinite(v) and v >= 0):
                raise ChangeDetectionError(f"ChangeDetection.reset_variance[{k!r}]: a finite variance >= 0, got {v}")

    def reset_diagonal(self, parameter_names: list[str]) -> np.ndarray:
        """The diagonal added to P for a structure with these parameters (ChangeDetectionError for a name it does
        not have)."""
        unknown = sorted(set(self.reset_variance) - set(parameter_names))
        if unknown:
            raise ChangeDetectionError(f"ChangeDetection.reset_variance: the model has no parameters {unknown}; "
                                       f"it has {parameter_names}")
        return np.array([float(self.reset_variance.get(n, 0.0)) for n in parameter_names])


class CusumDetector:
    """The two-sided CUSUM test of :class:`ChangeDetection` on a stream of prior residuals."""

    def __init__(self, settings: ChangeDetection) -> None:
        self.settings = settings
        self.reset()

    def reset(self) -> None:
        self.high = self.low = 0.0
        self.scale = float("nan")
        self.alarms = 0
        self.samples = 0

    @property
    def settling(self) -> int:
        """Residuals [1] the scale needs before the test may fire: 1 / (1 - scale_forgetting), its memory (a scale
        from a few residuals would standardise by noise and let the covariance step grow with 1 / scale^2)."""
        return int(round(1.0 / (1.0 - self.settings.scale_forgetting)))

    def update(self, residual: float) -> bool:
        """Feed one prior residual r_t [unit of B]; True when the test fires (the sums then restart at 0)."""
        if not math.isfinite(residual):
            return False
        st = self.settings
        size = abs(residual) * math.sqrt(math.pi / 2.0)
        if not math.isfinite(self.scale):
            self.scale = max(size, 1e-9)
            return False
        z = residual / max(self.scale, 1e-9)
        self.scale = st.scale_forgetting * self.scale + (1.0 - st.scale_forgetting) * size
        self.samples += 1
        if self.samples < self.settling:
            return False
        self.high = max(0.0, self.high + z - st.drift)
        self.low = max(0.0, self.low - z - st.drift)
        if self.high > st.threshold or self.low > st.threshold:
            self.high = self.low = 0.0
            self.alarms += 1
            return True
        return False


def gain_constant(estimator) -> float:
    """c of the estimator's gain L = W P a / (c + W a P a^T): R (output_noise) for the Kalman family, lambda
    (forgetting) otherwise, 1 where the estimator names neither."""
    config = getattr(estimator, "config", None)
    if config is None:
        return float(getattr(estimator, "forgetting", 1.0) or 1.0)
    if getattr(config, "covariance", "forgetting") != "forgetting" and getattr(config, "output_noise", None):
        return float(config.output_noise)
    return float(getattr(config, "forgetting", None) or 1.0)


def reset_covariance(estimator, diagonal: np.ndarray, noise_scale: float = 1.0) -> None:
    """Raise the parameter covariance of a recursive estimator by diag(diagonal) [parameter units^2]:
    P <- P + c diag(diagonal) / sigma^2 (module docstring), sigma = ``noise_scale`` [unit of B], the output noise
    (:attr:`CusumDetector.scale`); through the estimator's copyable state."""
    if not (math.isfinite(noise_scale) and noise_scale > 0):
        raise ChangeDetectionError(f"reset_covariance: noise_scale must be a finite scale > 0 [unit of B], got "
                                   f"{noise_scale!r}")
    state = estimator.state
    step = gain_constant(estimator) * np.asarray(diagonal, float) / noise_scale ** 2
    state.p = state.p + np.diag(step)
    estimator.set_state(state)
