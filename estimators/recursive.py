"""Recursive estimators: the online object (:class:`RecursiveEstimator`), whole-record runs and many-trip runs.

All three call :func:`roadload.estimators.kernel.run_record` (``run_many`` from worker threads, one trip per
call; the kernel releases the GIL), so ``update()`` sample by sample, ``run()`` over a record and
``run_many()`` over a trip axis give the same numbers.
"""

from __future__ import annotations

import copy
import os
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field

import numpy as np

from . import kernel as K
from .config import EstimatorConfig


class EstimatorInputError(ValueError):
    """Data handed to an estimator has the wrong shape or type; the message names the argument."""


@dataclass
class EstimatorState:
    """Inspectable, copyable state of a recursive estimator.

    x: X̂ (n,); p: P (n×n); scale: σ̂ [unit of B]; quantile: Q̂ (recursive quantile of ΔB², [unit of B]²);
    t: samples processed; n_skipped: non-finite samples skipped; n_rolled_back: updates that produced a
    non-finite X̂ or P and were undone; blowup_at: first sample index with max diag P above the blow-up level
    (-1: never, also set by the first covariance reset); p_diag_max: largest |diag P| an update produced;
    ring/ring_pos/ring_fill: delayed-instrument buffer; n_p_resets: covariance resets P ← P_0 of the safety
    net (P above the bound, non-finite or not positive definite; see :mod:`.kernel`).
    """

    x: np.ndarray
    p: np.ndarray
    scale: float
    quantile: float
    t: int
    n_skipped: int
    n_rolled_back: int
    blowup_at: int
    p_diag_max: float
    ring: np.ndarray
    ring_pos: int
    ring_fill: int
    n_p_resets: int = 0

    def copy(self) -> EstimatorState:
        return copy.deepcopy(self)


@dataclass
class EstimationResult:
    """Result of a run over a record (or, with a leading trip axis, over many records).

    X: X̂_t (T×n); P_diag: diag P_t (T×n); residual_prior: ΔB_t = B_t - A_t X̂_{t-1}; residual_post:
    B_t - A_t X̂_t; weights: W_t,t; scale: σ̂_t after the update [unit of B]; skipped: True where the sample
    was non-finite and skipped (residuals and weight are NaN there); n_skipped; n_rolled_back;
    p_blowup: max diag P exceeded the blow-up level (poor excitation without regularisation);
    p_blowup_at: first such sample index (-1: never); p_diag_max: largest diag P seen; state: final state;
    n_p_resets: covariance resets P ← P_0 by the safety net in this run (any reset also sets p_blowup).
    Arrays not requested (``store='x'`` or ``'final'``) are None.
    """

    X: np.ndarray | None
    P_diag: np.ndarray | None
    residual_prior: np.ndarray | None
    residual_post: np.ndarray | None
    weights: np.ndarray | None
    scale: np.ndarray | None
    skipped: np.ndarray | None
    n_skipped: int | np.ndarray
    n_rolled_back: int | np.ndarray
    p_blowup: bool | np.ndarray
    p_blowup_at: int | np.ndarray
    p_diag_max: float | np.ndarray
    state: EstimatorState | list[EstimatorState] = field(repr=False)
    n_p_resets: int | np.ndarray = 0


_STORE = {"final": K.STORE_FINAL, "x": K.STORE_X, "full": K.STORE_FULL}


def _as_float(arr, what: str) -> np.ndarray:
    try:
        out = np.asarray(arr, dtype=np.float64)
    except (TypeError, ValueError):
        raise EstimatorInputError(f"{what} must be numeric") from None
    return out


def kernel_array(arr: np.ndarray) -> np.ndarray:
    """C-contiguous, writeable float64 (one array type for the kernel: one compiled specialisation)."""
    return np.require(arr, dtype=np.float64, requirements=["C", "W", "A"])


class EstimateViews:
    """X̂_t and P_t of a recursive estimator (kept in ``_x``, ``_p``) as copies."""

    _x: np.ndarray
    _p: np.ndarray

    @property
    def x(self) -> np.ndarray:
        """X̂_t (copy)."""
        return self._x.copy()

    @property
    def p(self) -> np.ndarray:
        """P_t (copy)."""
        return self._p.copy()


class RecursiveEstimator(EstimateViews):
    """A recursive estimator of chapter 3 built from an :class:`EstimatorConfig` composition.

    ``update(a_t, b_t[, instrument])`` processes one sample and returns X̂_t; ``run(A, B[, instruments])``
    processes a whole record from the current state (and advances it). ``reset()`` returns to the initial
    state; ``copy()`` gives an independent estimator with the same state.
    """

    def __init__(self, config: EstimatorConfig):
        if not isinstance(config, EstimatorConfig):
            raise EstimatorInputError(f"config must be an EstimatorConfig, got {type(config).__name__}")
        self.config = config
        self.reset()

    # ------------------------------------------------------------------ state
    def reset(self) -> None:
        """Back to X̂_0 = x0, P_0 = p0, σ̂ = scale0, Q̂ = quantile0, empty instrument buffer."""
        arr = self.config.kernel_arrays
        n = self.config.n_params
        self._x = arr["x0"].copy()
        self._p = arr["P0"].copy()
        self._scalars = np.array([self.config.scale0 ** 2, self.config.quantile0, float(np.max(np.diag(arr["P0"])))])
        delay = self.config.instrument_delay  # set (default 4) whenever instruments are 'delayed'
        k = delay if self.config.instruments == "delayed" and delay is not None else 1
        self._instrument_ring = np.zeros((k, n))
        self._counters = np.zeros(K.N_CT, dtype=np.int64)
        self._counters[K.CT_BLOWUP_AT] = -1
        self._init_online()

    def _init_online(self) -> None:
        """Per-estimator constants of the one-sample path (kept to make update() cheap)."""
        n = self.config.n_params
        self._parts_final = self.config.kernel_parts(K.STORE_FINAL)
        self._no_output = K.outputs(1, n, K.STORE_FINAL)
        self._no_instruments = np.empty((0, n))
        self._sample = (np.empty((1, n)), np.empty(1), np.empty((1, n)))   # a_t, b_t, 𝔄_t of update()
        self._tag = K.size_tag(n)
        self._scratch = K.scratch(n)

    @property
    def _kernel_state(self) -> tuple:
        """The ``state`` record of the kernel (``kernel.STATE_FIELDS``): the estimator's own arrays."""
        return self._x, self._p, self._scalars, self._instrument_ring, self._counters

    @property
    def n_params(self) -> int:
        return self.config.n_params

    @property
    def scale(self) -> float:
        """σ̂_t [unit of B]."""
        return float(np.sqrt(self._scalars[K.SC_SIGMA2]))

    @property
    def quantile(self) -> float:
        """Q̂_t, the recursive quantile of the squared a posteriori correction."""
        return float(self._scalars[K.SC_QHAT])

    @property
    def state(self) -> EstimatorState:
        """A copy of the full state."""
        return EstimatorState(
            x=self._x.copy(), p=self._p.copy(), scale=self.scale, quantile=self.quantile,
            t=int(self._counters[K.CT_T]), n_skipped=int(self._counters[K.CT_SKIPPED]),
            n_rolled_back=int(self._counters[K.CT_ROLLED_BACK]), blowup_at=int(self._counters[K.CT_BLOWUP_AT]),
            p_diag_max=float(self._scalars[K.SC_PMAX]), ring=self._instrument_ring.copy(),
            ring_pos=int(self._counters[K.CT_RING_POS]), ring_fill=int(self._counters[K.CT_RING_FILL]),
            n_p_resets=int(self._counters[K.CT_P_RESETS]))

    def set_state(self, state: EstimatorState) -> None:
        """Restore a state taken with :attr:`state` (same configuration)."""
        n = self.config.n_params
        if state.x.shape != (n,) or state.p.shape != (n, n) or state.ring.shape != self._instrument_ring.shape:
            raise EstimatorInputError("state does not fit this estimator's configuration")
        self._x = np.array(state.x, dtype=float)
        self._p = np.array(state.p, dtype=float)
        self._scalars = np.array([state.scale ** 2, state.quantile, state.p_diag_max])
        self._instrument_ring = np.array(state.ring, dtype=float)
        self._counters = np.array([state.n_skipped, state.n_rolled_back, state.blowup_at, state.t,
                             state.ring_pos, state.ring_fill, state.n_p_resets], dtype=np.int64)

    def copy(self) -> RecursiveEstimator:
        """An independent estimator with the same configuration and state."""
        other = RecursiveEstimator.__new__(RecursiveEstimator)
        other.config = self.config
        other._x = self._x.copy()
        other._p = self._p.copy()
        other._scalars = self._scalars.copy()
        other._instrument_ring = self._instrument_ring.copy()
        other._counters = self._counters.copy()
        other._init_online()
        return other

    # ------------------------------------------------------------------ processing
    def _check(self, A, B, instruments):
        n = self.config.n_params
        A = _as_float(A, "A (regressors)")
        B = _as_float(B, "B (measured output)")
        if A.ndim != 2 or A.shape[1] != n:
            raise EstimatorInputError(f"A (regressors) must have shape (T, {n}), got {A.shape}")
        if B.ndim != 1 or B.shape[0] != A.shape[0]:
            raise EstimatorInputError(f"B (measured output) must have shape ({A.shape[0]},), got {B.shape}")
        if self.config.instruments == "user":
            if instruments is None:
                raise EstimatorInputError("this estimator uses user-supplied instruments: pass instruments "
                                          f"of shape ({A.shape[0]}, {n})")
            Z = _as_float(instruments, "instruments")
            if Z.shape != A.shape:
                raise EstimatorInputError(f"instruments must have shape {A.shape}, got {Z.shape}")
        else:
            if instruments is not None:
                raise EstimatorInputError(f"instruments given but the estimator uses instruments="
                                          f"{self.config.instruments!r}; set instruments='user' to pass them")
            Z = np.empty((0, n))
        return A, B, Z

    def update(self, a_t, b_t, instrument=None) -> np.ndarray:
        """Process one sample (a_t: n regressors, b_t: measured output, instrument: 𝔄_t if 'user').

        Returns X̂_t. A non-finite sample is skipped and counted (X̂ stays)."""
        n = self.config.n_params
        a = _as_float(a_t, "a_t")
        if a.size != n:
            raise EstimatorInputError(f"a_t must have {n} entries, got {a.size}")
        b = _as_float(b_t, "b_t")
        if b.size != 1:
            raise EstimatorInputError(f"b_t must be a scalar, got shape {np.shape(b_t)}")
        regressors, outputs, user = self._sample   # the one-sample record's own buffers
        regressors[0] = a.reshape(n)
        outputs[0] = b.reshape(())
        if instrument is None:
            if self.config.instruments == "user":
                raise EstimatorInputError("this estimator uses user-supplied instruments: pass instrument")
            Z = self._no_instruments
        else:
            if self.config.instruments != "user":
                raise EstimatorInputError(f"instrument given but the estimator uses instruments="
                                          f"{self.config.instruments!r}; set instruments='user' to pass them")
            z = _as_float(instrument, "instrument")
            if z.size != n:
                raise EstimatorInputError(f"instrument must have {n} entries, got {z.size}")
            user[0] = z.reshape(n)
            Z = user
        K.run_record((regressors, outputs, Z), self._parts_final, self._kernel_state, self._no_output, self._scratch,
                     self._tag)
        return self._x.copy()

    def _process(self, A, B, Z, store):
        T, n = A.shape
        out = K.outputs(T, n, store)
        K.run_record((A, B, Z), self.config.kernel_parts(store), self._kernel_state, out, K.scratch(n), self._tag)
        return out[0], out[1], list(out[2:])

    def run(self, A, B, instruments=None, store: str = "full") -> EstimationResult:
        """Process a whole record A (T×n), B (T,) from the current state; returns an EstimationResult.

        ``store``: 'full' (all per-sample arrays), 'x' (X̂_t only) or 'final' (state only)."""
        if store not in _STORE:
            raise EstimatorInputError(f"store must be one of {sorted(_STORE)}, got {store!r}")
        A, B, Z = self._check(A, B, instruments)
        skipped_before = int(self._counters[K.CT_SKIPPED])
        rolled_before = int(self._counters[K.CT_ROLLED_BACK])
        resets_before = int(self._counters[K.CT_P_RESETS])
        out_X, out_Pd, vecs = self._process(kernel_array(A), kernel_array(B), kernel_array(Z), _STORE[store])
        full = store == "full"
        skipped = np.isnan(vecs[0]) if full else None
        st = self.state
        return EstimationResult(
            X=out_X if store != "final" else None, P_diag=out_Pd if full else None,
            residual_prior=vecs[0] if full else None, residual_post=vecs[1] if full else None,
            weights=vecs[2] if full else None, scale=vecs[3] if full else None, skipped=skipped,
            n_skipped=st.n_skipped - skipped_before, n_rolled_back=st.n_rolled_back - rolled_before,
            p_blowup=st.blowup_at >= 0, p_blowup_at=st.blowup_at, p_diag_max=st.p_diag_max, state=st,
            n_p_resets=st.n_p_resets - resets_before)


def run_many(config: EstimatorConfig, A, B, instruments=None, store: str = "full",
             n_threads: int | None = None) -> EstimationResult:
    """Run independent records (trips) in parallel threads from the initial state of ``config``.

    A: K×T×n (or T×n shared by all trips; it is copied per trip), B: K×T; pad shorter trips with NaN (padding is
    skipped and counted). Results carry the trip axis first; counters are arrays of length K; ``state`` is a list.
    ``n_threads``: worker threads (default: all cores); the kernel releases the GIL, so trips run on all cores.
    Identical to running :meth:`RecursiveEstimator.run` on each trip (the same compiled function)."""
    if store not in _STORE:
        raise EstimatorInputError(f"store must be one of {sorted(_STORE)}, got {store!r}")
    if not isinstance(config, EstimatorConfig):
        raise EstimatorInputError(f"config must be an EstimatorConfig, got {type(config).__name__}")
    A, B, Z = _many_records(config, A, B, instruments)
    Kt, T, n = A.shape
    workers = (os.cpu_count() or 1) if n_threads is None else int(n_threads)
    if workers < 1:
        raise EstimatorInputError(f"n_threads must be >= 1, got {n_threads}")
    proto = RecursiveEstimator(config)
    states = [np.repeat(s[None], Kt, axis=0) for s in proto._kernel_state]   # X, P, scalars, rings, counters
    code = _STORE[store]
    parts = config.kernel_parts(code)
    out = K.outputs(T, n, code, trips=(Kt,))
    tag = K.size_tag(n)

    def one(r: int) -> None:
        # per-trip state in its own allocations: rows of X, P, ... share cache lines, and threads writing
        # neighbouring rows every sample (false sharing) ran no faster on two cores than on one
        state = tuple(s[r].copy() for s in states)
        K.run_record((A[r], B[r], Z[r]), parts, state, tuple(o[r] for o in out), K.scratch(n), tag)
        for s, own in zip(states, state):
            s[r] = own
    if workers == 1 or Kt == 1:
        for r in range(Kt):
            one(r)
    else:
        with ThreadPoolExecutor(max_workers=min(workers, Kt)) as pool:
            list(pool.map(one, range(Kt)))
    return _many_result(proto, states, out, code)


def _many_records(config: EstimatorConfig, A, B, instruments) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A (K×T×n), B (K×T) and the instruments (K×T×n, or K×0×n unless 'user') of :func:`run_many`, checked and
    as kernel arrays."""
    n = config.n_params
    B = _as_float(B, "B (measured output)")
    if B.ndim != 2:
        raise EstimatorInputError(f"B must have shape (K trips, T samples), got {B.shape}")
    Kt, T = B.shape
    A = _as_float(A, "A (regressors)")
    if A.ndim == 2 and A.shape == (T, n):
        A = np.broadcast_to(A, (Kt, T, n))
    if A.shape != (Kt, T, n):
        raise EstimatorInputError(f"A must have shape ({Kt}, {T}, {n}) or ({T}, {n}), got {A.shape}")
    if config.instruments == "user":
        if instruments is None:
            raise EstimatorInputError(f"user instruments required, shape ({Kt}, {T}, {n})")
        Z = _as_float(instruments, "instruments")
        if Z.shape != (Kt, T, n):
            raise EstimatorInputError(f"instruments must have shape ({Kt}, {T}, {n}), got {Z.shape}")
    else:
        if instruments is not None:
            raise EstimatorInputError("instruments given but the estimator does not use user instruments")
        Z = np.empty((Kt, 0, n))
    return kernel_array(A), kernel_array(B), kernel_array(Z)


def _many_result(proto: RecursiveEstimator, states: list[np.ndarray], out: tuple, code: int) -> EstimationResult:
    """The EstimationResult of :func:`run_many` from the per-trip states and outputs (trip axis first)."""
    X, P, scalars, rings, counters = states
    per_trip = []
    for r in range(X.shape[0]):
        e = proto.copy()
        e._x, e._p, e._scalars, e._instrument_ring, e._counters = X[r], P[r], scalars[r], rings[r], counters[r]
        per_trip.append(e.state)
    full = code == K.STORE_FULL
    blow = counters[:, K.CT_BLOWUP_AT]
    return EstimationResult(
        X=out[0] if code >= K.STORE_X else None, P_diag=out[1] if full else None,
        residual_prior=out[2] if full else None, residual_post=out[3] if full else None,
        weights=out[4] if full else None, scale=out[5] if full else None,
        skipped=np.isnan(out[2]) if full else None,
        n_skipped=counters[:, K.CT_SKIPPED].copy(), n_rolled_back=counters[:, K.CT_ROLLED_BACK].copy(),
        p_blowup=blow >= 0, p_blowup_at=blow.copy(), p_diag_max=scalars[:, K.SC_PMAX].copy(), state=per_trip,
        n_p_resets=counters[:, K.CT_P_RESETS].copy())
