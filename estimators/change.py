"""Change detection for recursive estimators: a two-sided CUSUM test on the prior residuals, and a covariance
reset when it fires, so that an estimator with long memory (RRLM with lambda = 0.999, section 5.5) follows a
step or a drift of the road load without the parameter noise of a short memory.

With the prior residual r_t = B_t - A_t X̂_{t-1} standardised by a recursive scale s_t (exponentially weighted
mean of |r|, times sqrt(pi/2) for a Gaussian), z_t = r_t / s_t, the cumulative sums

    g+_t = max(0, g+_{t-1} + z_t - nu),   g-_t = max(0, g-_{t-1} - z_t - nu)

grow only while the residuals keep one sign (a model that no longer fits), and the test fires when either exceeds
the threshold h. Then P <- P + diag(reset_variance) for the chosen parameters (the others keep their covariance),
which raises the gain of the next updates the way the text's random-walk (Kalman) estimators do continuously
(section 3.7), but only after a detected change.
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
        self.high = max(0.0, self.high + z - st.drift)
        self.low = max(0.0, self.low - z - st.drift)
        if self.high > st.threshold or self.low > st.threshold:
            self.high = self.low = 0.0
            self.alarms += 1
            return True
        return False


def reset_covariance(estimator, diagonal: np.ndarray) -> None:
    """P <- P + diag(diagonal) of a recursive estimator (through its copyable state)."""
    state = estimator.state
    state.p = state.p + np.diag(np.asarray(diagonal, float))
    estimator.set_state(state)
