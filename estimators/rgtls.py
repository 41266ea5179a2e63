"""Recursive generalised total least squares (RGTLS, Algorithm 3.8) with the noise covariance estimator
(NCE, eq. 3.43) built on a PKS bank (Figure 3.12).

Per sample with Z_t = [A_t B_t] (q = n + 1):
L = P Zᵀ / (λ + Z P Zᵀ); P = (I - L Z) P / λ; V = [X̂_{t-1}; -1]; V' = P (P̌_t V); X̂_t = -V'_{1:n} / V'_q.

P̌_t is fixed (``noise_covariance``; I gives RTLS, diag(0 … 0 1) the RLS direction) or estimated by the NCE:
Ž = Z - Ẑ from q PKS with one configuration (delay w_r), P̌_t = λ_N P̌_{t-1} + (1 - λ_N) Žᵀ Ž. RGTLS itself uses
the raw Z_t, so its estimates carry no smoother delay. Online ``update`` and batch ``run`` give the same numbers
(both call :func:`rgtls_record`).

Composition. "Apart from using Z_t instead of A_t, the update in Algorithm 3.8 Line 3 conforms with Algorithm 3.1
Line 4" (section 3.6.3): lines 3-4 are the catalogue kernel's own stages (:func:`~.kernel.covariance_products`,
:func:`~.kernel.gain` with W = 1, :func:`~.kernel.covariance_forgetting`) applied to Z_t; the sample reading,
output corrections and stored outputs are the kernel's stages too, the NCE's smoothers are the catalogue's PKS.
Two stages are RGTLS's own: :func:`generalised_inverse_iteration` (lines 5-7) and
:func:`noise_covariance_update` (eq. 3.43b). The record loop cannot be the catalogue's ``run_record``: there the
parameter vector and P share one dimension n and X̂_t = X̂_{t-1} + L ΔB_t, while here P is (n+1)×(n+1) over Z_t,
X̂_t comes from the inverse iteration with P̌_t (not from the gain), and P̌_t evolves per sample; a failed update
restores P_{t-1} (the catalogue's safety net resets to P_0 and skips overflowing samples instead).
"""

from __future__ import annotations

from collections import deque
from typing import Annotated, Any

import numpy as np
from roadload.jitcache import cached_njit
from pydantic import Strict, field_validator, model_validator

from .config import (BLOWUP_RATIO, FORGETTING, INITIAL_COVARIANCE, BlowupRatio, EstimatorConfigError, Forgetting,
                     ParameterCount, Real, _matrix, _setting, python_scalar, settings_dataclass, start_vector)
from .kernel import (STORE_FULL, _inline, covariance_forgetting, covariance_products, gain,
                     matrix_vector, output_correction, outputs, read_regressors, size_tag, store_sample)
from .pks import PKSDesign, PolynomialKalmanSmoother
from .recursive import EstimateViews, EstimationResult, EstimatorInputError, EstimatorState, kernel_array

# counters
_SKIP, _ROLLED, _BLOW, _T = 0, 1, 2, 3


@_inline
def noise_covariance_update(noise_cov, noise_row, lam_nce, q):
    """NCE, eq. 3.43b: P̌_t = λ_N P̌_{t-1} + (1 - λ_N) Žᵀ Ž with Ž_t = [Ǎ_t B̌_t] (a row with a non-finite entry,
    i.e. before the smoothers have an estimate, leaves P̌ as it is)."""
    for i in range(q):
        if not np.isfinite(noise_row[i]):
            return
    for i in range(q):
        for j in range(q):
            noise_cov[i, j] = lam_nce * noise_cov[i, j] + (1.0 - lam_nce) * noise_row[i] * noise_row[j]


@_inline
def generalised_inverse_iteration(X, P, noise_cov, V, W, n):
    """Algorithm 3.8 lines 5-7, one constrained generalised inverse iteration: V = [X̂_{t-1}; -1],
    V' = P_t (P̌_t V), X̂_t = -V'_{1:n} / V'_q. Returns False (X̂ kept) when V'_q is 0 or a result is not finite."""
    q = n + 1
    for i in range(n):
        V[i] = X[i]
    V[n] = -1.0
    matrix_vector(noise_cov, V, W, q)
    matrix_vector(P, W, V, q)
    ok = V[n] != 0.0 and np.isfinite(V[n])
    if ok:
        for i in range(n):
            xi = -V[i] / V[n]
            if not np.isfinite(xi):
                ok = False
            W[i] = xi
    for i in range(q):
        if not np.isfinite(P[i, i]):
            ok = False
    if ok:
        for i in range(n):
            X[i] = W[i]
    return ok


@_inline
def copy_square(target, source, q):
    """target ← source (q×q)."""
    for i in range(q):
        for j in range(q):
            target[i, j] = source[i, j]


@_inline
def track_blowup(P, scalars, counters, blowup, sample, q):
    """Largest max diag P so far (``scalars[0]``) and the first sample above the blow-up level (``counters``)."""
    pmax = P[0, 0]
    for i in range(1, q):
        if P[i, i] > pmax:
            pmax = P[i, i]
    if pmax > scalars[0]:
        scalars[0] = pmax
    if pmax > blowup and counters[_BLOW] < 0:
        counters[_BLOW] = sample


# _nrt=False: numba's private switch for reference counting (see kernel.run_record): without it every array handed
# to an inline stage is counted per sample, which made this loop 2x slower than one hand-written body
@cached_njit(_nrt=False)
def rgtls_record(record, noise_rows, settings, state, out, work, size_tag):
    """Algorithm 3.8 over a record, with the NCE (eq. 3.43b) fed by ``noise_rows`` Ž (T×q; NaN rows: no update).

    ``record`` = (A, B, unused), ``settings`` = (use_nce, λ, λ_N, blow-up level), ``state`` = (X̂ (n), P (q×q),
    P̌ (q×q), counters, scalars), ``out`` = the recursive kernel's output record (``kernel.OUTPUT_FIELDS``; the
    scale is sqrt P̌_qq, the weight 1), ``work`` = (5×q vectors, q×q matrix), ``size_tag`` = ``kernel.size_tag(n)``
    (n a compile-time constant, as in ``kernel.run_record``). Lines 3-4 are the catalogue's
    stages on Z_t = [A_t B_t] (products, gain, forgetting update of Algorithm 3.1); lines 5-7 are
    :func:`generalised_inverse_iteration`; an update that leaves X̂ or P non-finite is undone (P_{t-1} restored)."""
    use_nce, lam, lam_nce, blowup = settings
    X, P, noise_cov, counters, scalars = state
    T = record[1].shape[0]
    n = len(size_tag)
    q = n + 1
    vectors, P_prev = work
    z, P_z, L, V, W = vectors[0], vectors[1], vectors[2], vectors[3], vectors[4]
    inv_lam = 1.0 / lam
    for t in range(T):
        if use_nce:
            noise_covariance_update(noise_cov, noise_rows[t], lam_nce, q)
        b, probe = read_regressors(record, t, z, n)
        z[n] = b
        if not probe == 0.0:
            counters[_SKIP] += 1
            store_sample(t, X, P, np.nan, np.nan, np.nan, max(noise_cov[n, n], 0.0), out, STORE_FULL, n)
            continue
        r_prior = output_correction(z, X, b, n)
        copy_square(P_prev, P, q)
        s = covariance_products(P, z, z, P_z, P_z, q, True, False)
        gain(P_z, 1.0, s, lam, L, q)
        covariance_forgetting(P, P, L, P_z, P_z, inv_lam, q, True)
        if not generalised_inverse_iteration(X, P, noise_cov, V, W, n):
            counters[_ROLLED] += 1
            copy_square(P, P_prev, q)
        track_blowup(P, scalars, counters, blowup, counters[_T] + t, q)
        store_sample(t, X, P, r_prior, output_correction(z, X, b, n), 1.0, max(noise_cov[n, n], 0.0), out,
                     STORE_FULL, n)
    counters[_T] += T


@settings_dataclass()
class RGTLSConfig:
    """Settings of RGTLS (Algorithm 3.8) and of its noise covariance estimator (NCE, eq. 3.43), validated on
    construction (errors name the setting, the value and the expected range).

    n_params: n; forgetting: λ; noise_covariance: P̌ (scalar·I, q diagonal entries or q×q; the NCE's initial
    value when ``nce=True``); p0: initial P (q×q, scalar·I); x0: X̂_0 (default 0); nce: estimate P̌ online;
    nce_forgetting: λ_N (default λ); pks: the NCE's PKS design (a :class:`~.pks.PKSDesign` or its settings by
    name); blowup_ratio: a max diag P above this × max diag P_0 is reported as blow-up."""

    n_params: ParameterCount
    forgetting: Forgetting = FORGETTING
    noise_covariance: Any = 1.0
    p0: Any = INITIAL_COVARIANCE
    x0: Any = None
    nce: Annotated[bool, Strict()] = False
    nce_forgetting: Annotated[Real, _setting("forgetting factor lambda_N of the noise covariance estimator", ge=0.0,
                                             le=1.0)] | None = None
    pks: Any = None
    blowup_ratio: BlowupRatio = BLOWUP_RATIO
    name: str = "RGTLS"

    _numpy_scalars = field_validator("n_params", "nce", mode="before")(python_scalar)

    @model_validator(mode="after")
    def _matrices_and_defaults(self) -> "RGTLSConfig":
        """P̌ and P_0 as q×q symmetric PSD matrices, X̂_0 as n finite numbers, λ_N = λ unless given, the PKS design."""
        n = self.n_params
        q = n + 1
        self.noise_covariance = _matrix(self.noise_covariance, q, "noise_covariance (P̌)", psd=True)
        self.p0 = _matrix(self.p0, q, "p0", psd=True)
        self.x0 = start_vector(self.x0, n)
        if self.nce_forgetting is None:
            self.nce_forgetting = self.forgetting
        if not isinstance(self.pks, PKSDesign):
            if not isinstance(self.pks, (dict, type(None))):
                raise EstimatorConfigError(f"pks must be a PKSDesign or a dict of its settings, got {self.pks!r}")
            try:
                self.pks = PKSDesign(**(self.pks or {}))
            except EstimatorConfigError as exc:
                raise EstimatorConfigError(f"pks: {exc}") from None
        return self


class RecursiveGTLS(EstimateViews):
    """RGTLS (Algorithm 3.8), with a fixed noise covariance P̌ or the PKS-based NCE (eq. 3.43).

    Settings: those of :class:`RGTLSConfig`, by name. The P reported in results is the top-left n×n block of the
    q×q data-information inverse (not a parameter covariance)."""

    def __init__(self, n_params: int, **settings: Any):
        self.settings = cfg = RGTLSConfig(n_params, **settings)
        self.n_params, self.name, self.nce = cfg.n_params, cfg.name, cfg.nce
        self.forgetting = cfg.forgetting
        self.nce_forgetting = cfg.forgetting if cfg.nce_forgetting is None else cfg.nce_forgetting
        self.noise_covariance, self.p0, self.x0 = cfg.noise_covariance, cfg.p0, cfg.x0
        self.blowup = cfg.blowup_ratio * float(np.max(np.diag(self.p0)))
        self.reset()

    def reset(self) -> None:
        q = self.n_params + 1
        self._x = self.x0.copy()
        self._p = self.p0.copy()
        self._pc = self.noise_covariance.copy()
        self._ct = np.array([0, 0, -1, 0], dtype=np.int64)
        self._sc = np.array([float(np.max(np.diag(self.p0)))])
        self._smoothers = [PolynomialKalmanSmoother(self.settings.pks) for _ in range(q)]
        self._raw: deque[np.ndarray] = deque(maxlen=self.settings.pks.delay + 1)

    @property
    def noise_covariance_estimate(self) -> np.ndarray:
        """P̌_t (q×q)."""
        return self._pc.copy()

    def _noise_rows(self, A, B) -> np.ndarray:
        """Ž rows for the samples of this call (NaN where the smoothers have no estimate yet)."""
        T, n = A.shape
        q = n + 1
        Zr = np.column_stack([A, B])
        if not self.nce:
            return np.empty((0, q))
        d = self.settings.pks.delay
        smoothed = np.column_stack([s.run(Zr[:, i]).X @ s._rows[0] for i, s in enumerate(self._smoothers)])
        hist = np.array(self._raw) if len(self._raw) else np.empty((0, q))
        allz = np.vstack([hist, Zr])
        off = hist.shape[0]
        rows = np.full((T, q), np.nan)
        for t in range(T):
            src = off + t - d
            if src >= 0 and self._ct[_T] + t - d >= 0:
                rows[t] = allz[src] - smoothed[t]
        for row in Zr[-(d + 1):]:
            self._raw.append(row)
        return rows

    def run(self, A, B, instruments=None, store: str = "full") -> EstimationResult:
        """Process a record A (T×n), B (T,) from the current state; returns an EstimationResult."""
        if instruments is not None:
            raise EstimatorInputError("RGTLS takes no instruments")
        A = kernel_array(np.asarray(A, dtype=float))
        B = kernel_array(np.asarray(B, dtype=float))
        n = self.n_params
        if A.ndim != 2 or A.shape[1] != n or B.shape != (A.shape[0],):
            raise EstimatorInputError(f"need A (T, {n}) and B (T,), got {A.shape} and {B.shape}")
        T = A.shape[0]
        noise_rows = kernel_array(self._noise_rows(A, B))
        out = outputs(T, n, STORE_FULL)
        before = self._ct.copy()
        work = (np.empty((5, n + 1)), np.empty((n + 1, n + 1)))
        rgtls_record((A, B, A[:0]), noise_rows, (self.nce, self.forgetting, self.nce_forgetting, self.blowup),
                     (self._x, self._p, self._pc, self._ct, self._sc), out, work, size_tag(n))
        skipped = np.isnan(out[2])
        full = store == "full"
        return EstimationResult(
            X=out[0] if store != "final" else None, P_diag=out[1] if full else None,
            residual_prior=out[2] if full else None, residual_post=out[3] if full else None,
            weights=out[4] if full else None, scale=out[5] if full else None,
            skipped=skipped if full else None, n_skipped=int(self._ct[_SKIP] - before[_SKIP]),
            n_rolled_back=int(self._ct[_ROLLED] - before[_ROLLED]), p_blowup=bool(self._ct[_BLOW] >= 0),
            p_blowup_at=int(self._ct[_BLOW]), p_diag_max=float(self._sc[0]), state=self.state)

    def update(self, a_t, b_t, instrument=None) -> np.ndarray:
        """Process one sample; returns X̂_t."""
        a = np.asarray(a_t, dtype=float).reshape(1, -1)
        if a.shape[1] != self.n_params:
            raise EstimatorInputError(f"a_t must have {self.n_params} entries, got {a.shape[1]}")
        self.run(a, np.asarray([b_t], dtype=float).reshape(1), instrument, store="final")
        return self._x.copy()

    @property
    def state(self) -> EstimatorState:
        return EstimatorState(x=self._x.copy(), p=self._p.copy(), scale=float(np.sqrt(max(self._pc[-1, -1], 0))),
                              quantile=float("nan"), t=int(self._ct[_T]), n_skipped=int(self._ct[_SKIP]),
                              n_rolled_back=int(self._ct[_ROLLED]), blowup_at=int(self._ct[_BLOW]),
                              p_diag_max=float(self._sc[0]), ring=np.empty((0, self.n_params)), ring_pos=0,
                              ring_fill=0)
