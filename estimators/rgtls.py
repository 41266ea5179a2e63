"""Recursive generalised total least squares (RGTLS, Algorithm 3.8) with the noise covariance estimator
(NCE, eq. 3.43) built on a PKS bank (Figure 3.12).

Per sample with Z_t = [A_t B_t] (q = n + 1):
L = P Zᵀ / (λ + Z P Zᵀ); P = (I - L Z) P / λ; V = [X̂_{t-1}; -1]; V' = P (P̌_t V); X̂_t = -V'_{1:n} / V'_q.

P̌_t is fixed (``noise_covariance``; I gives RTLS, diag(0 … 0 1) the RLS direction) or estimated by the NCE:
Ž = Z - Ẑ from q PKS with one configuration (delay w_r), P̌_t = λ_N P̌_{t-1} + (1 - λ_N) Žᵀ Ž. RGTLS itself uses
the raw Z_t, so its estimates carry no smoother delay. Online ``update`` and batch ``run`` give the same numbers
(both call :func:`rgtls_record`).
"""

from __future__ import annotations

from collections import deque

import numpy as np
from roadload.jitcache import cached_njit

from .config import EstimatorConfigError, _matrix
from .pks import PolynomialKalmanSmoother
from .recursive import EstimationResult, EstimatorInputError, EstimatorState, kernel_array

# counters
_SKIP, _ROLLED, _BLOW, _T = 0, 1, 2, 3


@cached_njit
def rgtls_record(A, B, Nz, use_nce, lam, lam_nce, blowup, X, P, Pc, ct, sc,
                 out_X, out_Pdiag, out_rprior, out_rpost, out_scale):
    """Algorithm 3.8 over a record; Nz (T×q) are NCE noise rows (NaN rows: no NCE update)."""
    T = B.shape[0]
    n = X.shape[0]
    q = n + 1
    z = np.empty(q)
    Pz = np.empty(q)
    V = np.empty(q)
    W = np.empty(q)
    Pp = np.empty((q, q))
    inv_lam = 1.0 / lam
    for t in range(T):
        if use_nce:
            okn = True
            for i in range(q):
                if not np.isfinite(Nz[t, i]):
                    okn = False
            if okn:
                for i in range(q):
                    for j in range(q):
                        Pc[i, j] = lam_nce * Pc[i, j] + (1.0 - lam_nce) * Nz[t, i] * Nz[t, j]
        valid = np.isfinite(B[t])
        for i in range(n):
            z[i] = A[t, i]
            if not np.isfinite(z[i]):
                valid = False
        z[n] = B[t]
        r0 = B[t]
        for i in range(n):
            r0 -= z[i] * X[i]
        if not valid:
            ct[_SKIP] += 1
            for i in range(n):
                out_X[t, i] = X[i]
                out_Pdiag[t, i] = P[i, i]
            out_rprior[t] = np.nan
            out_rpost[t] = np.nan
            out_scale[t] = np.sqrt(max(Pc[n, n], 0.0))
            continue
        for i in range(q):
            for j in range(q):
                Pp[i, j] = P[i, j]
        s = 0.0
        for i in range(q):
            acc = 0.0
            for j in range(q):
                acc += P[i, j] * z[j]
            Pz[i] = acc
            s += z[i] * acc
        g = 1.0 / (lam + s)
        for i in range(q):
            for j in range(i, q):
                val = (P[i, j] - g * Pz[i] * Pz[j]) * inv_lam
                P[i, j] = val
                P[j, i] = val
        for i in range(n):
            V[i] = X[i]
        V[n] = -1.0
        for i in range(q):
            acc = 0.0
            for j in range(q):
                acc += Pc[i, j] * V[j]
            W[i] = acc
        for i in range(q):
            acc = 0.0
            for j in range(q):
                acc += P[i, j] * W[j]
            V[i] = acc
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
        else:
            ct[_ROLLED] += 1
            for i in range(q):
                for j in range(q):
                    P[i, j] = Pp[i, j]
        pmax = P[0, 0]
        for i in range(1, q):
            if P[i, i] > pmax:
                pmax = P[i, i]
        if pmax > sc[0]:
            sc[0] = pmax
        if pmax > blowup and ct[_BLOW] < 0:
            ct[_BLOW] = ct[_T] + t
        rp = B[t]
        for i in range(n):
            rp -= z[i] * X[i]
            out_X[t, i] = X[i]
            out_Pdiag[t, i] = P[i, i]
        out_rprior[t] = r0
        out_rpost[t] = rp
        out_scale[t] = np.sqrt(max(Pc[n, n], 0.0))
    ct[_T] += T


class RecursiveGTLS:
    """RGTLS (Algorithm 3.8), with a fixed noise covariance P̌ or the PKS-based NCE (eq. 3.43).

    n_params: n; forgetting: λ; noise_covariance: P̌ (scalar·I, q diagonal entries or q×q; the NCE's initial
    value when ``nce=True``); p0: initial P (q×q, scalar·I default 100); x0: X̂_0; nce: estimate P̌ online;
    nce_forgetting: λ_N (default λ); pks: settings of the NCE's PKS bank (n_params, forgetting, window_left,
    window_right, p0). The P reported in results is the top-left n×n block of the q×q data-information
    inverse (not a parameter covariance)."""

    def __init__(self, n_params: int, forgetting: float = 0.999, noise_covariance=1.0, p0=100.0, x0=None,
                 nce: bool = False, nce_forgetting: float | None = None, pks: dict | None = None,
                 blowup_ratio: float = 1e6, name: str = "RGTLS"):
        if isinstance(n_params, bool) or not isinstance(n_params, (int, np.integer)) or n_params < 1:
            raise EstimatorConfigError(f"n_params must be a positive integer, got {n_params!r}")
        self.n_params = n = int(n_params)
        q = n + 1
        if not (0.0 < float(forgetting) <= 1.0):
            raise EstimatorConfigError(f"forgetting must lie in (0, 1], got {forgetting}")
        lam_n = forgetting if nce_forgetting is None else nce_forgetting
        if not (0.0 <= float(lam_n) <= 1.0):
            raise EstimatorConfigError(f"nce_forgetting must lie in [0, 1], got {lam_n}")
        if not (np.isfinite(blowup_ratio) and blowup_ratio > 1):
            raise EstimatorConfigError(f"blowup_ratio must be > 1, got {blowup_ratio}")
        self.forgetting = float(forgetting)
        self.nce_forgetting = float(lam_n)
        self.noise_covariance = _matrix(noise_covariance, q, "noise_covariance (P̌)", psd=True)
        self.p0 = _matrix(p0, q, "p0", psd=True)
        x0 = np.zeros(n) if x0 is None else np.asarray(x0, dtype=float).reshape(-1)
        if x0.shape != (n,) or not np.all(np.isfinite(x0)):
            raise EstimatorConfigError(f"x0 must be {n} finite numbers")
        self.x0 = x0
        self.nce = bool(nce)
        pks = dict(pks or {})
        try:
            self._pks_proto = PolynomialKalmanSmoother(**pks)
        except TypeError as exc:
            raise EstimatorConfigError(f"pks settings: {exc}") from None
        self.blowup = float(blowup_ratio) * float(np.max(np.diag(self.p0)))
        self.name = name
        self.reset()

    def reset(self) -> None:
        q = self.n_params + 1
        self._x = self.x0.copy()
        self._p = self.p0.copy()
        self._pc = self.noise_covariance.copy()
        self._ct = np.array([0, 0, -1, 0], dtype=np.int64)
        self._sc = np.array([float(np.max(np.diag(self.p0)))])
        self._smoothers = [PolynomialKalmanSmoother(**self._pks_kwargs()) for _ in range(q)]
        self._raw: deque[np.ndarray] = deque(maxlen=self._pks_proto.delay + 1)

    def _pks_kwargs(self) -> dict:
        d = self._pks_proto.design
        return dict(n_params=d.n_params, forgetting=d.forgetting, window_left=d.window_left,
                    window_right=d.window_right, p0=d.p0)

    @property
    def x(self) -> np.ndarray:
        return self._x.copy()

    @property
    def p(self) -> np.ndarray:
        return self._p.copy()

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
        d = self._pks_proto.delay
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
        Nz = kernel_array(self._noise_rows(A, B))
        out = [np.empty((T, n)), np.empty((T, n)), np.empty(T), np.empty(T), np.empty(T)]
        before = self._ct.copy()
        rgtls_record(A, B, Nz, self.nce, self.forgetting, self.nce_forgetting, self.blowup, self._x, self._p,
                     self._pc, self._ct, self._sc, *out)
        skipped = np.isnan(out[2])
        full = store == "full"
        return EstimationResult(
            X=out[0] if store != "final" else None, P_diag=out[1] if full else None,
            residual_prior=out[2] if full else None, residual_post=out[3] if full else None,
            weights=np.where(skipped, np.nan, 1.0) if full else None, scale=out[4] if full else None,
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
