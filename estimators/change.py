"""Change detection for recursive estimators: a two-sided CUSUM test on the prior residuals, and a covariance
reset when it fires, so that an estimator with long memory (RRLM with lambda = 0.999, section 5.5) follows a
step or a drift of the road load without the parameter noise of a short memory.

With the prior residual r_t = B_t - A_t X̂_{t-1} standardised by a recursive scale s_t (exponentially weighted
mean of |r|, times sqrt(pi/2) for a Gaussian), z_t = r_t / s_t, the cumulative sums

    g+_t = max(0, g+_{t-1} + z_t - nu),   g-_t = max(0, g-_{t-1} - z_t - nu)

grow only while the residuals keep one sign (a model that no longer fits), and the test fires when either exceeds
the threshold h.

Gusts make the residuals correlated (a 1.5 m/s gust of 5 s time constant is a 20-30 N drag error lasting tens of
samples at 10 Hz): standardised sample by sample, such runs of one sign look like a change, and the per-sample test
fired about 24 times in 4 km of the drift condition. So the test can run on block means instead: ``window``
residuals are averaged, r̄_k, and the block means are standardised by their own recursive scale s̄_k (learnt from
the block means, so it includes whatever correlation the blocks keep), z_k = r̄_k / s̄_k. After an alarm the test
stays quiet for ``dwell`` residuals while the estimator re-converges (its own transient residuals are no new
change). Then the covariance of the chosen parameters grows by ``reset_variance`` (the others keep
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
    forgetting of the recursive residual scale (per residual, and per block mean for the test); reset_variance:
    diagonal added to P when the test fires, per parameter name (units of the parameter squared); parameters not
    named keep their covariance; window [residuals]: the test runs on means of this many residuals (1: on every
    residual); dwell [residuals]: after an alarm the test cannot fire again for this many residuals."""

    drift: float = 0.5
    threshold: float = 12.0
    scale_forgetting: float = 0.99
    reset_variance: dict[str, float] = field(default_factory=lambda: {"m_V f_r0": 25.0, "rho_a/2 A_V c_x": 0.01})
    window: int = 1
    dwell: int = 0

    def __post_init__(self) -> None:
        for name in ("drift", "threshold"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise ChangeDetectionError(f"ChangeDetection.{name}: a finite number > 0 [1], got {value!r}")
        for name in ("window", "dwell"):
            value = getattr(self, name)
            if not (isinstance(value, int) and not isinstance(value, bool) and value >= (1 if name == "window" else 0)):
                low = 1 if name == "window" else 0
                raise ChangeDetectionError(f"ChangeDetection.{name}: an integer >= {low} [residuals], got {value!r}")
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


#: the test on block means that the closed loop runs (``online@RRLM+cusum``): blocks of 50 residuals (about 5.5 s of
#: triggered rows, a gust's time constant), the block scale's memory 10 blocks, threshold 8, and 300 residuals
#: (about 30 s) of dwell after an alarm. Chosen on cruise-control drives of generated hilly roads, seeds 100-104,
#: with the drift condition's wind (3 m/s, 1.5 m/s gusts), RRLM on M4: the per-sample test fired 18-29 times in
#: 4 km there, this one 0-1 times, and it fires 8-30 s after a 300 kg payload step on 4 of the 5 roads.
GUST_ROBUST = ChangeDetection(threshold=8.0, scale_forgetting=0.9, window=50, dwell=300)


class CusumDetector:
    """The two-sided CUSUM test of :class:`ChangeDetection` on a stream of prior residuals."""

    def __init__(self, settings: ChangeDetection) -> None:
        self.settings = settings
        self.reset()

    def reset(self) -> None:
        self.high = self.low = 0.0
        self.scale = float("nan")  # [unit of B] the residuals' scale (the output noise sigma of the reset)
        self.block_scale = float("nan")  # [unit of B] the block means' scale (the test's)
        self.alarms = 0
        self.samples = 0
        self.blocks = 0
        self._block_sum = 0.0
        self._block_n = 0
        self._quiet = 0  # residuals left of the dwell after an alarm

    @property
    def settling(self) -> int:
        """Block means [1] the test's scale needs before the test may fire: 1 / (1 - scale_forgetting), its memory
        (a scale from a few residuals would standardise by noise and let the covariance step grow with
        1 / scale^2)."""
        return int(round(1.0 / (1.0 - self.settings.scale_forgetting)))

    def update(self, residual: float) -> bool:
        """Feed one prior residual r_t [unit of B]; True when the test fires (the sums then restart at 0)."""
        if not math.isfinite(residual):
            return False
        st = self.settings
        size = abs(residual) * math.sqrt(math.pi / 2.0)
        self.scale = (max(size, 1e-9) if not math.isfinite(self.scale)
                      else st.scale_forgetting * self.scale + (1.0 - st.scale_forgetting) * size)
        self.samples += 1
        self._quiet = max(self._quiet - 1, 0)
        self._block_sum += residual
        self._block_n += 1
        if self._block_n < st.window:
            return False
        mean = self._block_sum / self._block_n
        self._block_sum, self._block_n = 0.0, 0
        return self._test(mean)

    def _test(self, mean: float) -> bool:
        """One standardised block mean through the cumulative sums (module docstring)."""
        st = self.settings
        size = abs(mean) * math.sqrt(math.pi / 2.0)
        if not math.isfinite(self.block_scale):
            self.block_scale = max(size, 1e-9)
            return False
        z = mean / max(self.block_scale, 1e-9)
        self.block_scale = st.scale_forgetting * self.block_scale + (1.0 - st.scale_forgetting) * size
        self.blocks += 1
        if self.blocks < self.settling or self._quiet > 0:
            return False
        self.high = max(0.0, self.high + z - st.drift)
        self.low = max(0.0, self.low - z - st.drift)
        if self.high > st.threshold or self.low > st.threshold:
            self.high = self.low = 0.0
            self.alarms += 1
            self._quiet = st.dwell
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
