"""Statistics that a few samples cannot drive: the robust, regime-normalised target of the candidate ranking and its
null calibration by a wild bootstrap over segments.

Why: on data the simulator did not write, the force residual is heavy-tailed — braking transients, gear shifts,
gusts leave kN residuals on a few % of the samples while cruising scatters by a few N. A squared-error ranking on
the raw residual is then decided by those few samples (any regressor that is large there, e.g. the brake force,
"explains" them). Three steps keep that from happening:

1. **Per-regime normalisation.** Every row belongs to a *cell* (driving mode traction / coast / regen / braking
   x the seven bins of dv/dt of :mod:`.regimes`); cells with fewer than ``min_cell`` training rows join one rest
   cell. Per cell: median m_c and MAD scale s_c = 1.4826 med|r - m_c| (eq. 3.14) of the residual on the
   training rows, floored at ``scale_floor`` x the overall MAD scale (default 1: a noisy regime such as
   braking or hard acceleration is weighted down, a quiet one is never weighted up — else the few segments of the
   quietest cell decide). Rows are weighted with w = 1/s_c², i.e. the loss is the squared *standardised*
   residual z = r / s_c.
2. **Winsorising** (a bounded loss): r is clipped to m_c ± ``clip`` s_c before fitting and judging, so no sample
   counts for more than ``clip``² in z² (Huber-like influence bound; a level shift of a whole cell moves m_c and
   is not clipped away).
3. **Braking rows judged only by brake candidates.** Rows in friction braking or within ``brake_hold`` s after
   it: the regressors of every candidate that is not about the friction brake are zeroed there, so those rows
   neither fit nor judge them (the brake candidates see them; every candidate is judged on the same rows).

The held-out gain of a candidate is the out-of-fold reduction of Σ w (r_w - A X)² on the training segments (fits:
weighted least squares of r_w on the candidate's regressors, folds by whole segments as in :mod:`.selection`),
relative to the loss of the model before the step. Its null distribution comes from the **wild bootstrap over
blocks** (Rademacher signs, one per 10 s block of the training segments; blocks nest in the split's 60 s segments, so
each lies in one CV fold): under "the candidate adds nothing" the residual of the model
before the step is sign-flipped segment by segment, r⁽ᵇ⁾ = r̂₀ + ε_seg (r_w - r̂₀), which keeps its heavy tails and
its autocorrelation within a segment but breaks any systematic link to the regressors. The step's statistic is
the largest relative gain over the candidates in the pool (a max-statistic, so taking the best of many
candidates is paid for: family-wise level); p = (1 + #{b: max gain⁽ᵇ⁾ >= observed}) / (B + 1). All of it is
computed from per-segment sufficient statistics (Σ w a aᵀ, Σ w a r, Σ w r² per segment), so B = 199 draws cost
milliseconds per candidate.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np
import pandas as pd

from roadload.estimators.batch import mad_scale

from .errors import DiagnosisError
from .records import Record

ACCEL_EDGES = np.array([-np.inf, -1.5, -0.5, -0.1, 0.1, 0.5, 1.5, np.inf])
MODES = ("traction", "coast", "regen", "braking")


@dataclass
class RegimeCell(Record):
    """One cell of the robust target: its label, training rows, median and MAD scale of the residual [N]."""

    cell: str
    n_train: int
    median: float
    scale: float


@dataclass
class TargetSummary(Record):
    """The robust target in the report: its cells, the braking rows and the training segments."""

    cells: list[RegimeCell]
    n_braking_rows: int
    n_training_segments: int


@dataclass
class RobustTarget:
    """The residual as the ranking sees it (see module doc): r_w [N] winsorised per cell, w = 1/s_c² [1/N²],
    cell index and scale s_c [N] per row, ``braking`` rows (friction braking or just after), segment index of
    training rows (-1 elsewhere) and the fold of each segment."""

    r_w: np.ndarray
    weight: np.ndarray
    cell: np.ndarray
    scale: np.ndarray
    braking: np.ndarray
    segment: np.ndarray
    fold_of_segment: np.ndarray
    n_folds: int
    cells: list[RegimeCell]

    @property
    def n_segments(self) -> int:
        return int(self.fold_of_segment.size)

    def describe(self) -> TargetSummary:
        return TargetSummary(self.cells, int(self.braking.sum()), self.n_segments)


def regime_cells(table: pd.DataFrame) -> np.ndarray:
    """Cell index per row: mode (traction, coast, regen, braking; other = 4) x the 7 dv/dt bins [m/s²]."""
    n = len(table)
    if "mode" in table.columns:
        mode = table["mode"].to_numpy()
        m = np.full(n, len(MODES), dtype=int)
        for i, name in enumerate(MODES):
            m[mode == name] = i
    else:
        m = np.zeros(n, dtype=int)
    a = table["acceleration"].to_numpy(dtype=float) if "acceleration" in table.columns else np.zeros(n)
    ab = np.clip(np.searchsorted(ACCEL_EDGES, np.nan_to_num(a), side="right") - 1, 0, len(ACCEL_EDGES) - 2)
    return m * (len(ACCEL_EDGES) - 1) + ab


def braking_rows(table: pd.DataFrame, brake_hold: float = 1.0) -> np.ndarray:
    """Rows in friction braking (mode 'braking': brake pressure above the threshold of :mod:`.table`) or within
    ``brake_hold`` [s] after."""
    n = len(table)
    out = np.zeros(n, dtype=bool)
    if "mode" in table.columns:
        out |= (table["mode"] == "braking").to_numpy()
    if "time_since_brake" in table.columns:
        tsb = table["time_since_brake"].to_numpy(dtype=float)
        out |= np.isfinite(tsb) & (tsb < brake_hold)
    return out


def robust_target(table: pd.DataFrame, residual: np.ndarray, train: np.ndarray, segments: np.ndarray,
                  fold: np.ndarray, n_folds: int, *, clip: float = 5.0, min_cell: int = 100,
                  scale_floor: float = 1.0, brake_hold: float = 1.0) -> RobustTarget:
    """The :class:`RobustTarget` of ``residual`` [N] (see module doc); statistics from the ``train`` rows."""
    r = np.asarray(residual, dtype=float)
    train = np.asarray(train, dtype=bool)
    if r.shape[0] != len(table) or train.shape[0] != len(table):
        raise DiagnosisError(f"residual ({r.shape[0]}) / training mask ({train.shape[0]}) and table ({len(table)}) "
                             "differ in length")
    if train.sum() < 20:
        raise DiagnosisError(f"{int(train.sum())} training rows are too few for the robust statistics (need >= 20)")
    if not clip > 0:
        raise DiagnosisError(f"clip must be > 0 (in MAD scales), got {clip}")
    cell = regime_cells(table)
    counts = np.bincount(cell[train], minlength=cell.max() + 1)
    rest = -1
    small = counts[cell] < min_cell
    cell = np.where(small, rest, cell)
    overall = float(mad_scale(r[train])) if train.any() else 1.0
    floor = max(scale_floor * overall, 1e-6)
    scale = np.full(r.shape, max(overall, floor))
    med = np.full(r.shape, float(np.median(r[train])))
    cells = []
    for c in np.unique(cell):
        sel = cell == c
        tr = sel & train
        if tr.sum() >= 10:
            m_c = float(np.median(r[tr]))
            s_c = max(float(mad_scale(r[tr])), floor)
        else:
            m_c, s_c = float(np.median(r[train])), max(overall, floor)
        med[sel], scale[sel] = m_c, s_c
        if c >= 0:
            mode = MODES[c // 7] if c // 7 < len(MODES) else "other"
            lo, hi = ACCEL_EDGES[c % 7], ACCEL_EDGES[c % 7 + 1]
            label = f"{mode}, dv/dt in [{lo:g}, {hi:g})"
        else:
            label = f"rest (cells with < {min_cell} training rows)"
        cells.append(RegimeCell(label, int(tr.sum()), m_c, s_c))
    r_w = med + np.clip(r - med, -clip * scale, clip * scale)
    weight = 1.0 / scale ** 2
    seg = np.full(r.shape, -1, dtype=np.int64)
    segs, inv = np.unique(np.asarray(segments)[train], return_inverse=True)
    seg[train] = inv
    fold = np.asarray(fold)
    fold_of = np.full(segs.size, -1, dtype=int)
    fold_of[inv] = fold[train]
    return RobustTarget(r_w, weight, cell, scale, braking_rows(table, brake_hold), seg, fold_of, int(n_folds),
                        cells)


# ====================================================================================== CV from segment sums
@dataclass
class SegmentSums:
    """Per training segment s: G_s = Σ w a aᵀ, b0_s = Σ w a y0, b1_s = Σ w a e, c00 = Σ w y0², c01 = Σ w y0 e,
    c11 = Σ w e² of a design A (scaled columns), a fixed part y0 and a sign-flipped part e (y = y0 + ε_s e)."""

    G: np.ndarray
    b0: np.ndarray
    b1: np.ndarray
    c00: np.ndarray
    c01: np.ndarray
    c11: np.ndarray


def segment_sums(A: np.ndarray, target: RobustTarget, y0: np.ndarray, e: np.ndarray) -> SegmentSums:
    """The :class:`SegmentSums` of design ``A`` (n x k; k may be 0) on the training rows."""
    rows = target.segment >= 0
    s = target.segment[rows]
    S = target.n_segments
    w = target.weight[rows]
    y0r, er = np.asarray(y0, dtype=float)[rows], np.asarray(e, dtype=float)[rows]
    A = np.asarray(A, dtype=float).reshape(len(target.segment), -1)[rows]
    k = A.shape[1]
    G = np.zeros((S, k, k))
    b0 = np.zeros((S, k))
    b1 = np.zeros((S, k))
    wA = A * w[:, None]
    for i in range(k):
        b0[:, i] = np.bincount(s, weights=wA[:, i] * y0r, minlength=S)
        b1[:, i] = np.bincount(s, weights=wA[:, i] * er, minlength=S)
        for j in range(i, k):
            G[:, i, j] = G[:, j, i] = np.bincount(s, weights=wA[:, i] * A[:, j], minlength=S)
    c00 = np.bincount(s, weights=w * y0r ** 2, minlength=S)
    c01 = np.bincount(s, weights=w * y0r * er, minlength=S)
    c11 = np.bincount(s, weights=w * er ** 2, minlength=S)
    return SegmentSums(G, b0, b1, c00, c01, c11)


def extended_sums(base: SegmentSums, base_A: np.ndarray, A: np.ndarray, target: RobustTarget, y0: np.ndarray,
                  e: np.ndarray) -> SegmentSums:
    """The :class:`SegmentSums` of the design [base_A, A] from the base's own sums: only the cross terms with the
    new columns are summed (a step's base is shared by all its candidates; the result equals
    ``segment_sums(np.hstack([base_A, A]), ...)``)."""
    rows = target.segment >= 0
    s = target.segment[rows]
    S = target.n_segments
    w = target.weight[rows]
    A = np.asarray(A, dtype=float).reshape(len(target.segment), -1)[rows]
    B = np.asarray(base_A, dtype=float).reshape(len(target.segment), -1)[rows]
    kb, kc = B.shape[1], A.shape[1]
    k = kb + kc
    G = np.zeros((S, k, k))
    G[:, :kb, :kb] = base.G
    b0 = np.zeros((S, k))
    b1 = np.zeros((S, k))
    b0[:, :kb], b1[:, :kb] = base.b0, base.b1
    wA = A * w[:, None]
    y0r, er = np.asarray(y0, dtype=float)[rows], np.asarray(e, dtype=float)[rows]
    for i in range(kc):
        b0[:, kb + i] = np.bincount(s, weights=wA[:, i] * y0r, minlength=S)
        b1[:, kb + i] = np.bincount(s, weights=wA[:, i] * er, minlength=S)
        for j in range(kb):
            G[:, kb + i, j] = G[:, j, kb + i] = np.bincount(s, weights=wA[:, i] * B[:, j], minlength=S)
        for j in range(i, kc):
            G[:, kb + i, kb + j] = G[:, kb + j, kb + i] = np.bincount(s, weights=wA[:, i] * A[:, j], minlength=S)
    return SegmentSums(G, b0, b1, base.c00, base.c01, base.c11)


def cv_loss(sums: SegmentSums, fold_of_segment: np.ndarray, n_folds: int, signs: np.ndarray) -> np.ndarray:
    """Out-of-fold weighted squared loss Σ w (y - A X̂_fold)² for each row of ``signs`` (B x segments, ±1) with
    y = y0 + ε_s e; X̂_fold: weighted least squares on the other folds' segments. Returns (B,)."""
    E = np.asarray(signs, dtype=float)
    yy = sums.c00[None] + 2.0 * E * sums.c01[None] + sums.c11[None]          # (B, S)
    k = sums.G.shape[1]
    if k == 0:
        return yy.sum(axis=1)
    b = sums.b0[None] + E[:, :, None] * sums.b1[None]                      # (B, S, k)
    G_tot = sums.G.sum(axis=0)
    b_tot = b.sum(axis=1)
    loss = np.zeros(E.shape[0])
    for f in range(n_folds):
        sf = fold_of_segment == f
        if not sf.any():
            continue
        G_f = sums.G[sf].sum(axis=0)
        b_f = b[:, sf].sum(axis=1)
        G_tr = G_tot - G_f
        ridge = 1e-10 * max(float(np.trace(G_tr)), 1e-300) * np.eye(k)
        X = np.linalg.solve(G_tr + ridge, (b_tot - b_f).T).T                # (B, k)
        loss += yy[:, sf].sum(axis=1) - 2.0 * np.einsum("bi,bi->b", X, b_f) \
            + np.einsum("bi,ij,bj->b", X, G_f, X)
    return loss


def scaled(A: np.ndarray, weight: np.ndarray) -> np.ndarray:
    """Columns scaled to unit weighted RMS (conditioning of the normal equations; fits are scale-free)."""
    A = np.asarray(A, dtype=float)
    if A.ndim == 1:
        A = A[:, None]
    if A.shape[1] == 0:
        return A
    s = np.sqrt(np.mean(A ** 2 * weight[:, None], axis=0))
    s[~(s > 0)] = 1.0
    return A / s


def weighted_fit(A: np.ndarray, y: np.ndarray, weight: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """X̂ of weighted least squares y ≈ A X on ``rows`` (original column units)."""
    A = np.asarray(A, dtype=float)
    if A.shape[1] == 0:
        return np.zeros(0)
    s = np.sqrt(np.mean(A[rows] ** 2 * weight[rows, None], axis=0))
    s[~(s > 0)] = 1.0
    sw = np.sqrt(weight[rows])
    X, *_ = np.linalg.lstsq((A[rows] / s) * sw[:, None], y[rows] * sw, rcond=1e-10)
    return X / s


def rademacher(n_draws: int, n_segments: int, rng: np.random.Generator) -> np.ndarray:
    """(1 + n_draws) x n_segments signs: row 0 all +1 (the observed data), then the null draws."""
    E = rng.integers(0, 2, size=(n_draws + 1, n_segments)) * 2.0 - 1.0
    E[0] = 1.0
    return E


@dataclass
class StepStatistics:
    """Relative out-of-fold gains of the candidates in one step: ``observed`` (c,), ``null`` (B, c) and the
    base loss; :meth:`p_value` of the max-statistic and :meth:`marginal_p` per candidate."""

    observed: np.ndarray
    null: np.ndarray
    loss_before: float
    variant: np.ndarray

    def p_value(self, j: int) -> float:
        """Family-wise p of the step choosing candidate j: P(max over candidates of a null gain >= gain_j)."""
        mx = self.null.max(axis=1) if self.null.size else np.zeros(0)
        return float((1 + np.sum(mx >= self.observed[j])) / (mx.size + 1))

    def marginal_p(self, j: int) -> float:
        col = self.null[:, j]
        return float((1 + np.sum(col >= self.observed[j])) / (col.size + 1))


def step_statistics(base: np.ndarray, candidates: Sequence[Sequence[np.ndarray]], target: RobustTarget,
                    signs: np.ndarray) -> StepStatistics:
    """Relative out-of-fold gains of every candidate over the ``base`` design (n x k0), observed and under the
    wild segment bootstrap (see module doc). ``candidates``: per candidate, its design variants (one per value of
    a shape grid; the best variant is taken, in every draw alike)."""
    w = target.weight
    rows = target.segment >= 0
    y = target.r_w
    base_s = scaled(base, w)
    if base_s.shape[1]:
        X0 = weighted_fit(base_s, y, w, rows)
        y0 = base_s @ X0
    else:
        y0 = np.zeros_like(y)
    e = y - y0
    base_sums = segment_sums(base_s, target, y0, e)
    L0 = cv_loss(base_sums, target.fold_of_segment, target.n_folds, signs)
    norm = float(np.sum(w[rows] * y[rows] ** 2))     # the loss of the sim as is (relative gains share it)
    gains = np.zeros((signs.shape[0], len(candidates)))
    variant = np.zeros(len(candidates), dtype=int)
    for j, variants in enumerate(candidates):
        best = None
        for i, A in enumerate(variants):
            L1 = cv_loss(extended_sums(base_sums, base_s, scaled(A, w), target, y0, e), target.fold_of_segment,
                         target.n_folds, signs)
            if best is None or L1[0] < best[0]:
                variant[j] = i
            best = L1 if best is None else np.minimum(best, L1)
        gains[:, j] = (L0 - best) / norm if norm > 0 else 0.0
    return StepStatistics(gains[0], gains[1:], float(L0[0] / norm) if norm > 0 else float("nan"), variant)


def winsorised(y: np.ndarray, rows: np.ndarray, clip: float) -> tuple[np.ndarray, np.ndarray]:
    """y clipped at median ± clip MAD scales (of the training rows) and the weights 1/scale²."""
    med = float(np.median(y[rows]))
    s = max(float(1.4826 * np.median(np.abs(y[rows] - med))), 1e-6)
    return med + np.clip(y - med, -clip * s, clip * s), np.full(y.shape, 1.0 / s ** 2)
