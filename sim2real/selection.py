"""Which effect causes the gap: candidates fitted on training data, judged on held-out data (section 3.2.3), with
ΔAIC/ΔBIC (eq. 3.5b, 3.6b) alongside, ranked, and a greedy forward selection that stops when the held-out gain
is not significant.

Data are split by whole segments (default 60 s of one trip): every k-th segment of a trip (random phase) is the
*test* part, kept away from all fitting and used only for the before/after gap measures; the remaining
*training* segments are dealt into folds for cross-validation. The target is the force residual
y = F_xV,measured - F_xV,sim [N]; a candidate set is fitted to y (Huber M-estimation by default,
:func:`roadload.estimators.batch.m_estimate`) and judged by the out-of-fold squared error. A held-out gain is
significant when the block-bootstrap 95 % interval of the per-sample loss reduction lies above 0 (blocks of
10 s, so autocorrelation does not fake significance) and the gain is at least ``min_gain`` of the sim's
original out-of-fold MSE; a
candidate must also remove at least ``min_explained`` of what the flexible reference (:mod:`.reference`) can
remove, otherwise it is a partial fit and the rest is left unexplained, never forced onto it.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable, Sequence

import numpy as np
import pandas as pd

from roadload.estimators.batch import BatchInputError, least_squares, m_estimate

from .catalog import CandidateEffect, get_candidate
from .errors import DiagnosisError
from .forcemodel import SimForceModel, columns_of
from .records import Record
from .reference import AdditiveRegimeModel
from .robust import StepStatistics, TargetSummary, rademacher, robust_target, step_statistics
from .stats import block_ids, cluster_covariance

#: how an acceptance check's reason starts when the effect lies along a direction the calibration held at a bound
#: of its physical range (:mod:`.held`): reported as it is, not as an implausible value
NOT_SEPARABLE = "not separable from the calibration's base error"


# ============================================================================================ split
@dataclass
class SplitSummary(Record):
    """Sizes of a split: valid, training and held-out (test) rows, CV folds, segments and held-out segments."""

    n_valid: int
    n_train: int
    n_test: int
    n_folds: int
    n_segments: int
    n_test_segments: int


@dataclass
class Split:
    """valid: rows used at all; test: held-out rows; fold: CV fold of training rows (-1 elsewhere);
    blocks: 10 s bootstrap blocks; segments: the split units."""

    valid: np.ndarray
    test: np.ndarray
    fold: np.ndarray
    n_folds: int
    blocks: np.ndarray
    segments: np.ndarray

    @property
    def train(self) -> np.ndarray:
        return self.valid & ~self.test

    def describe(self) -> SplitSummary:
        return SplitSummary(int(self.valid.sum()), int(self.train.sum()), int(self.test.sum()), self.n_folds,
                            int(np.unique(self.segments[self.valid]).size),
                            int(np.unique(self.segments[self.test]).size))


def make_split(table: pd.DataFrame, *, segment_length: float = 60.0, test_fraction: float = 1 / 3,
               n_folds: int = 5, block_length: float = 10.0, seed: int = 0) -> Split:
    """Training / test split by segments (see module doc); rows with ``valid`` False are in neither part."""
    for c in ("trip", "t", "valid"):
        if c not in table.columns:
            raise DiagnosisError(f"the diagnosis table lacks the column {c!r}")
    if not 0 < test_fraction < 1:
        raise DiagnosisError(f"test_fraction must lie in (0, 1), got {test_fraction}")
    if n_folds < 2:
        raise DiagnosisError(f"n_folds must be >= 2, got {n_folds}")
    trip = table["trip"].to_numpy()
    t = table["t"].to_numpy(dtype=float)
    valid = table["valid"].to_numpy(dtype=bool)
    seg = block_ids(trip, t, segment_length)
    blocks = block_ids(trip, t, block_length)
    rng = np.random.default_rng(seed)
    every = max(2, int(round(1.0 / test_fraction)))
    test_segs: set[int] = set()
    train_segs: list[int] = []
    for k in pd.unique(trip):
        segs = np.unique(seg[(trip == k) & valid])
        phase = int(rng.integers(0, every))
        for i, s in enumerate(segs):
            (test_segs.add(int(s)) if (i + phase) % every == 0 else train_segs.append(int(s)))
    if len(train_segs) < n_folds or not test_segs:
        raise DiagnosisError(f"too little valid data to split: {len(train_segs)} training and {len(test_segs)} test "
                             f"segments of {segment_length:g} s (need >= {n_folds} and >= 1); give longer trips")
    test = np.isin(seg, list(test_segs)) & valid
    fold = np.full(len(table), -1)
    order = rng.permutation(len(train_segs))
    fold_of = {train_segs[j]: int(i % n_folds) for i, j in enumerate(order)}
    tr = valid & ~test
    fold[tr] = [fold_of[int(s)] for s in seg[tr]]
    return Split(valid, test, fold, n_folds, blocks, seg)


# ============================================================================================ fitting
@dataclass
class Fit:
    X: np.ndarray
    cov: np.ndarray | None


def fit_linear(A: np.ndarray, y: np.ndarray, rows: np.ndarray, robust: bool = True,
               blocks: np.ndarray | None = None) -> Fit:
    """X̂ of y ≈ A X on ``rows`` (columns scaled internally), with the block covariance when blocks are given."""
    As, ys = A[rows], y[rows]
    if As.shape[0] <= As.shape[1]:
        raise DiagnosisError(f"{As.shape[0]} samples cannot determine {As.shape[1]} parameters")
    scale = np.sqrt(np.mean(As ** 2, axis=0))
    scale[~(scale > 0)] = 1.0
    try:
        res = (m_estimate(As / scale, ys, "huber", max_iter=15, tol=1e-5) if robust
               else least_squares(As / scale, ys))
    except BatchInputError as exc:
        raise DiagnosisError(f"fit failed: {exc}") from None
    X = res.X / scale
    cov = None
    if blocks is not None:
        cov = cluster_covariance(As, ys - As @ X, blocks[rows], res.weights)
    return Fit(X, cov)


def cv_predict(A: np.ndarray | None, y: np.ndarray, table: pd.DataFrame, split: Split, robust: bool = True,
               reference: bool = False) -> np.ndarray:
    """Out-of-fold prediction of y on the training rows (NaN elsewhere); A None = no candidate (prediction 0);
    ``reference`` adds the additive regime model fitted on the fold's training residual."""
    pred = np.full(y.shape, np.nan)
    for k in range(split.n_folds):
        tr = split.train & (split.fold != k)
        te = split.train & (split.fold == k)
        if not te.any():
            continue
        p_tr = np.zeros(int(tr.sum()))
        p_te = np.zeros(int(te.sum()))
        if A is not None:
            X = fit_linear(A, y, tr, robust).X
            p_tr, p_te = A[tr] @ X, A[te] @ X
        if reference:
            ref = AdditiveRegimeModel().fit(table[tr], y[tr] - p_tr)
            p_te = p_te + ref.predict(table[te])
        pred[te] = p_te
    return pred


# ============================================================================================ candidates
@dataclass
class Design:
    """Regressor columns of a set of (candidate, shape) choices."""

    A: np.ndarray
    names: list[str]
    units: list[str]
    owner: list[str]


def design(choices: Sequence[tuple[CandidateEffect, float | None]], model: SimForceModel,
           cols: dict[str, np.ndarray]) -> Design:
    blocks, names, units, owner = [], [], [], []
    for cand, shape in choices:
        ext = cand.structure(model, shape)
        own = ext.terms[-len(cand.terms(model, shape)):]
        for term in own:
            col = np.asarray(term.build(cols), dtype=float)
            blocks.append(np.nan_to_num(col, nan=0.0, posinf=0.0, neginf=0.0))
            names.append(term.parameter)
            units.append(term.unit)
            owner.append(cand.name)
    return Design(np.column_stack(blocks), names, units, owner)


@dataclass
class CandidateResult:
    """One candidate judged alone against the sim as is (see :func:`rank_candidates`)."""

    name: str
    description: str
    shape: float | None
    shape_name: str
    parameters: dict[str, float]
    std_errors: dict[str, float]
    units: dict[str, str]
    cv_mse: float
    baseline_cv_mse: float
    improvement: float
    gain: tuple[float, float, float]
    significant: bool
    aic: float
    bic: float
    delta_aic: float = float("nan")
    delta_bic: float = float("nan")
    explained_fraction: float = float("nan")
    sim_effect: str | None = None
    sim_parameters: dict[str, float] | None = None
    regime_hint: str = ""
    null_p: float = float("nan")
    size: float = float("nan")

    def to_dict(self) -> dict:
        return {"null_p": self.null_p, "size_rms": self.size, "name": self.name,
                "description": self.description, "shape": self.shape,
                "shape_name": self.shape_name, "parameters": self.parameters, "std_errors": self.std_errors,
                "units": self.units, "cv_mse": self.cv_mse, "baseline_cv_mse": self.baseline_cv_mse,
                "heldout_improvement": self.improvement, "heldout_gain": list(self.gain),
                "significant": self.significant, "aic": self.aic, "bic": self.bic, "delta_aic": self.delta_aic,
                "delta_bic": self.delta_bic, "explained_fraction": self.explained_fraction,
                "sim_effect": self.sim_effect, "sim_parameters": self.sim_parameters,
                "regime_hint": self.regime_hint}


def information_criteria(sse: float, m: int, o: int) -> tuple[float, float]:
    """AIC (eq. 3.5b) and BIC (eq. 3.6b) of a least-squares fit: m log(SSE/m) + 2o and m log(SSE/m) + o log m."""
    base = m * np.log(max(sse, 1e-300) / m)
    return float(base + 2 * o), float(base + o * np.log(m))


@dataclass
class Selector:
    """Everything the ranking needs: the table, the residual y, the split, the sim's force model; ``side``: which
    candidates apply ("force": y is the force residual [N]; "power": the battery-power residual [W]).

    ``base_design`` (n x k, optional): the base calibration's regressors (:mod:`.base`, already zero where they
    must not fit). They join every design — the null model, every candidate, the reference and the final fit —
    so each candidate is judged by the nested comparison base vs base + candidate (the base refitted jointly with
    it, against the same wild-bootstrap null): an effect only partly collinear with a base parameter keeps the
    part the base cannot explain, and a candidate that *is* a base direction gains nothing."""

    table: pd.DataFrame
    residual: np.ndarray
    split: Split
    model: SimForceModel
    robust: bool = True
    n_boot: int = 400
    seed: int = 0
    min_gain: float = 0.02
    min_explained: float = 0.5
    side: str = "force"
    n_null: int = 199
    alpha: float = 0.01
    clip: float = 5.0
    plausible: Callable[[CandidateEffect, dict, float | None], str | None] | None = None
    min_size: float = 0.0
    base_design: np.ndarray | None = None
    consistent: Callable[[CandidateEffect, dict, float | None, float], str | None] | None = None
    cols: dict[str, np.ndarray] = field(init=False)
    baseline_loss: np.ndarray = field(init=False)

    def __post_init__(self) -> None:
        self.cols = columns_of(self.table)
        y = np.asarray(self.residual, dtype=float)
        if y.shape[0] != len(self.table):
            raise DiagnosisError("residual and table differ in length")
        bad = self.split.valid & ~np.isfinite(y)
        if bad.any():
            raise DiagnosisError(f"the residual is not finite on {int(bad.sum())} valid rows")
        self.residual = y
        self.baseline_loss = np.where(self.split.train, y ** 2, np.nan)
        self.rng = np.random.default_rng(self.seed)
        # the null's resampling unit: the 10 s bootstrap blocks (nested in the 60 s split segments, so every block
        # lies in one fold); segments would leave too few sign patterns on short trips
        self.target = robust_target(self.table, y, self.split.train, self.split.blocks, self.split.fold,
                                    self.split.n_folds, clip=self.clip)
        self.signs = rademacher(self.n_null, self.target.n_segments, self.rng)
        if self.base_design is not None:
            B = np.asarray(self.base_design, dtype=float).reshape(len(self.table), -1)
            self.base_design = np.nan_to_num(B) if B.shape[1] else None

    # ---------------------------------------------------------------- helpers
    def _mse(self, pred: np.ndarray) -> tuple[float, np.ndarray]:
        loss = np.where(self.split.train, (self.residual - np.nan_to_num(pred)) ** 2, np.nan)
        return float(np.nanmean(loss)), loss

    def choose_shape(self, cand: CandidateEffect, prior: Sequence[tuple[CandidateEffect, float | None]] = ()
                     ) -> float | None:
        """The shape value (e.g. τ) with the smallest training SSE, profiled on the candidate's grid."""
        if not cand.shape_grid:
            return None
        best, best_sse = None, np.inf
        tr = self.split.train
        for sh in cand.shape_grid:
            d = design(list(prior) + [(cand, sh)], self.model, self.cols)
            X = fit_linear(d.A, self.residual, tr, self.robust).X
            sse = float(np.sum((self.residual[tr] - d.A[tr] @ X) ** 2))
            if sse < best_sse:
                best, best_sse = sh, sse
        return best

    def usable(self, names: Sequence[str]) -> tuple[list[CandidateEffect], dict[str, str]]:
        """Candidates whose needed columns the table has; the others with the reason."""
        ok, skipped = [], {}
        valid = self.split.valid
        sub = {k: np.asarray(v)[valid] for k, v in self.cols.items()}
        for n in names:
            cand = get_candidate(n)
            if cand.side != self.side:      # the other side's residual is not this selector's
                continue
            miss = cand.missing(sub)
            if miss:
                skipped[cand.name] = f"needs {miss}, which the trips do not provide"
            else:
                ok.append(cand)
        return ok, skipped

    def evaluate(self, choices: list[tuple[CandidateEffect, float | None]], reference: bool = False
                 ) -> tuple[float, np.ndarray]:
        A = design(choices, self.model, self.cols).A if choices else None
        pred = cv_predict(A, self.residual, self.table, self.split, self.robust, reference)
        return self._mse(pred)

    def final_fit(self, choices: list[tuple[CandidateEffect, float | None]]) -> tuple[Design, Fit]:
        """Huber fit of the choices on the training rows; the regressors of candidates that are not about the
        friction brake are zero on braking rows while fitting (those rows fit brake candidates only), the returned
        design is the full one (for predicting everywhere)."""
        d = design(choices, self.model, self.cols)
        A = d.A.copy()
        brake = np.array([get_candidate(o).is_brake for o in d.owner], dtype=bool)
        A[np.ix_(self.target.braking, ~brake)] = 0.0
        if self.base_design is not None:    # the base refitted jointly (its columns are masked already)
            k = self.base_design.shape[1]
            A = np.hstack([self.base_design, A])
            d = Design(np.hstack([self.base_design, d.A]), [f"base {i}" for i in range(k)] + d.names,
                       ["-"] * k + d.units, ["base"] * k + d.owner)
        return d, fit_linear(A, self.residual, self.split.train, self.robust, self.split.blocks)

    def fitted_columns(self, d: Design) -> np.ndarray:
        """The design as :meth:`final_fit` fits it: columns of candidates that are not about the friction brake
        zero on braking rows (base columns come masked)."""
        A = d.A.copy()
        mask = np.array([o != "base" and not get_candidate(o).is_brake for o in d.owner], dtype=bool)
        A[np.ix_(self.target.braking, mask)] = 0.0
        return A

    # ---------------------------------------------------------------- robust design
    def candidate_columns(self, cand: CandidateEffect, shape: float | None) -> np.ndarray:
        """The candidate's regressors as the robust ranking sees them: zero on braking rows unless it is a
        brake candidate (:mod:`.robust`, step 3)."""
        A = design([(cand, shape)], self.model, self.cols).A
        if not cand.is_brake:
            A = np.where(self.target.braking[:, None], 0.0, A)
        return A

    def _variants(self, cand: CandidateEffect) -> list[np.ndarray]:
        return [self.candidate_columns(cand, sh) for sh in cand.shapes()]

    def _base(self, chosen: Sequence[tuple[CandidateEffect, float | None]]) -> np.ndarray:
        """The design a step's candidates are added to: the base block (when given) and the chosen effects."""
        parts = [] if self.base_design is None else [self.base_design]
        parts += [self.candidate_columns(c, sh) for c, sh in chosen]
        return np.hstack(parts) if parts else np.zeros((len(self.table), 0))

    def _reference_loss(self, chosen: Sequence[tuple[CandidateEffect, float | None]]) -> float:
        """Robust out-of-fold loss (relative to the sim as is) of the chosen effects plus the flexible reference
        (cached per set of chosen effects)."""
        key = tuple((c.name, sh) for c, sh in chosen)
        cache = self.__dict__.setdefault("_ref_cache", {})
        if key not in cache:
            cache[key] = self._reference_loss_uncached(chosen)
        return cache[key]

    def _reference_loss_uncached(self, chosen: Sequence[tuple[CandidateEffect, float | None]]) -> float:
        A = design(list(chosen), self.model, self.cols).A if chosen else None
        if self.base_design is not None:
            A = self.base_design if A is None else np.hstack([self.base_design, A])
        pred = cv_predict(A, self.residual, self.table, self.split, self.robust, reference=True)
        t = self.target
        rows = t.segment >= 0
        norm = float(np.sum(t.weight[rows] * t.r_w[rows] ** 2))
        loss = float(np.sum(t.weight[rows] * (t.r_w[rows] - np.nan_to_num(pred[rows])) ** 2))
        return loss / norm if norm > 0 else float("nan")

    def effect_size(self, d: Design, fit: Fit, name: str) -> float:
        """RMS of one effect's fitted contribution over the training rows [N, or W on the power side]. With a
        ``base_design`` the contribution is taken net of the other columns (base and other effects): the part of
        it they cannot take, i.e. what the effect changes in the fitted model — a candidate nearly collinear with
        the base otherwise shows a large contribution that the refitted base cancels."""
        own = np.array([i for i, o in enumerate(d.owner) if o == name], dtype=int)
        tr = self.split.train
        A = self.fitted_columns(d) if self.base_design is not None else d.A
        contrib = A[np.ix_(tr, own)] @ fit.X[own]
        if not contrib.size:
            return 0.0
        if self.base_design is not None:
            other = np.array([i for i, o in enumerate(d.owner) if o != name], dtype=int)
            if other.size:
                B = A[np.ix_(tr, other)]
                coef, *_ = np.linalg.lstsq(B, contrib, rcond=None)
                contrib = contrib - B @ coef
        return float(np.sqrt(np.mean(contrib ** 2)))

    # ---------------------------------------------------------------- ranking
    def rank(self, names: Sequence[str]) -> tuple[list[CandidateResult], dict[str, str]]:
        """Every usable candidate alone over the sim as is: robust out-of-fold gain (:mod:`.robust`) with its
        null p-value from the wild segment bootstrap; parameters from the Huber fit on the training rows
        (braking rows only for brake candidates). Sorted by gain, largest first."""
        cands, skipped = self.usable(names)
        tr = self.split.train
        m = int(tr.sum())
        aic0, bic0 = information_criteria(float(np.sum(self.residual[tr] ** 2)), m, 0)
        ok: list[CandidateEffect] = []
        variants: list[list[np.ndarray]] = []
        for cand in cands:
            try:
                variants.append(self._variants(cand))
                ok.append(cand)
            except DiagnosisError as exc:
                skipped[cand.name] = str(exc)
        stats = step_statistics(self._base([]), variants, self.target, self.signs)
        ref_loss = self._reference_loss([])
        results = []
        for j, cand in enumerate(ok):
            try:
                results.append(self._judge_alone(j, cand, stats, ref_loss))
            except DiagnosisError as exc:
                skipped[cand.name] = str(exc)
        results.sort(key=lambda r: -r.improvement)
        amin = min([aic0] + [r.aic for r in results])
        bmin = min([bic0] + [r.bic for r in results])
        for r in results:
            r.delta_aic, r.delta_bic = r.aic - amin, r.bic - bmin
        self.baseline_info = BaselineInfo(1.0, ref_loss, aic0, bic0, aic0 - amin, bic0 - bmin,
                                          NullSettings(int(self.signs.shape[0] - 1), self.alpha),
                                          self.target.describe())
        return results, skipped

    def _judge_alone(self, j: int, cand: CandidateEffect, stats: StepStatistics, ref_loss: float
                     ) -> CandidateResult:
        """The :class:`CandidateResult` of candidate ``j`` of a ranking step (DiagnosisError when its fit fails)."""
        shape = cand.shapes()[int(stats.variant[j])]
        d, fit = self.final_fit([(cand, shape)])
        tr = self.split.train
        m = int(tr.sum())
        gain = float(stats.observed[j])
        sse = float(np.sum((self.residual[tr] - d.A[tr] @ fit.X) ** 2))
        aic, bic = information_criteria(sse, m, d.A.shape[1] + (1 if cand.shape_grid else 0))
        params, errors, units = fitted_parameters(d, fit, cand.name)
        explainable = 1.0 - min(ref_loss, 1.0 - gain)
        frac = float(np.clip(gain / explainable, -np.inf, 1.0)) if explainable > 0 else 0.0
        p = stats.marginal_p(j)
        size = self.effect_size(d, fit, cand.name)
        null_j = stats.null[:, j]
        interval = (gain, float(np.quantile(null_j, 1 - self.alpha)) if null_j.size else gain,
                    float(null_j.max()) if null_j.size else gain)
        res = CandidateResult(
            cand.name, cand.description, shape, cand.shape_name, params, errors, units, 1.0 - gain, 1.0, gain,
            interval, bool(p <= self.alpha and gain >= self.min_gain and size >= self.min_size), aic, bic,
            explained_fraction=frac, sim_effect=cand.sim_effect,
            sim_parameters=_safe_sim_parameters(cand, params, shape, self.model), regime_hint=cand.regime_hint)
        res.null_p = p
        res.size = size
        return res

    # ---------------------------------------------------------------- greedy forward selection
    def forward(self, ranked: list[CandidateResult], max_effects: int = 4) -> list[SelectionStep]:
        """Greedy forward selection over the significant ranked candidates (top 6).

        Each step takes the candidate with the largest robust out-of-fold gain given the ones already chosen
        and accepts it when (a) the family-wise null p of the step (max-statistic over the pool, wild segment
        bootstrap) is <= alpha, (b) the gain is >= min_gain of the sim's original robust loss, (c) it removes
        >= min_explained of what the flexible reference can remove, and (d) its fitted value maps to a
        physically plausible simulator setting (``plausible``), and (e) its fitted contribution's RMS is >=
        min_size. A candidate failing (c), (d) or (e) is reported with the reason and the next one is tried; the
        selection stops at the first step failing (a) or (b)."""
        pool = [(get_candidate(r.name), r.shape) for r in ranked if r.significant][:6]
        chosen: list[tuple[CandidateEffect, float | None]] = []
        steps: list[SelectionStep] = []
        cur = 1.0
        while pool and len(chosen) < max_effects:
            step, choice = self._judge_step(chosen, pool, len(steps) + 1)
            steps.append(step)
            pool = [(c, s) for c, s in pool if c.name != choice[0].name]
            skippable = ("too small", "partial fit", "final fit failed")
            if step.implausible or (not step.accepted and step.reason.startswith(skippable)):
                continue      # the next candidate may still be a real one
            if not step.accepted:
                break
            chosen.append(choice)
            cur = step.robust_loss_after
        self.chosen = chosen
        self.robust_loss_after = cur
        return steps

    def _judge_step(self, chosen: list[tuple[CandidateEffect, float | None]],
                    pool: list[tuple[CandidateEffect, float | None]], number: int
                    ) -> tuple[SelectionStep, tuple[CandidateEffect, float | None]]:
        """The best candidate of the pool given the chosen ones, judged by the acceptance rules of
        :meth:`forward`."""
        stats = step_statistics(self._base(chosen), [self._variants(c) for c, _ in pool], self.target, self.signs)
        j = int(np.argmax(stats.observed))
        cand = pool[j][0]
        shape = cand.shapes()[int(stats.variant[j])]
        gain = float(stats.observed[j])
        p = stats.p_value(j)
        ref_loss = self._reference_loss(chosen)
        after = stats.loss_before - gain
        explainable = stats.loss_before - min(ref_loss, after)
        frac = float(min(gain / explainable, 1.0)) if explainable > 0 else 0.0
        accepted = bool(p <= self.alpha and gain >= self.min_gain and frac >= self.min_explained)
        reason = ("accepted" if accepted else
                  f"held-out gain not beyond the null (p = {p:.3f} > {self.alpha})" if p > self.alpha else
                  f"gain {gain:.3f} of the original gap, below {self.min_gain}" if gain < self.min_gain else
                  f"partial fit: explains {frac:.2f} of the removable remainder (< {self.min_explained})")
        size, implausible = self._size_and_plausibility(chosen, cand, shape, accepted)
        if accepted and not np.isfinite(size):  # the final fit raised: its error is the reason, not a size of nan
            accepted = False
            reason = f"final fit failed: {implausible}"
            implausible = None
        if accepted and not size >= self.min_size:
            accepted = False
            reason = f"too small: the fitted effect's RMS {size:.3g} is below {self.min_size:g}"
        if accepted and implausible:
            accepted = False
            # a direction the calibration held at a bound is no implausible value: it says so itself (.held)
            reason = implausible if implausible.startswith(NOT_SEPARABLE) else f"implausible: {implausible}"
        else:
            implausible = None
        null_q = float(np.quantile(stats.null.max(axis=1), 1 - self.alpha)) if stats.null.size else float("nan")
        step = SelectionStep(number, cand.name, shape, stats.loss_before, after,
                             float(gain / stats.loss_before) if stats.loss_before > 0 else 0.0, gain, p, null_q,
                             [gain, null_q, float("nan")], ref_loss, frac, accepted, size, implausible, reason)
        return step, (cand, shape)

    def _size_and_plausibility(self, chosen: list[tuple[CandidateEffect, float | None]], cand: CandidateEffect,
                               shape: float | None, accepted: bool) -> tuple[float, str | None]:
        """The RMS of the candidate's fitted contribution next to the chosen ones, and why its fitted value is no
        plausible simulator setting or is inconsistent with the other side's evidence (``consistent``; None when it
        is plausible, or when the step is not accepted anyway)."""
        try:
            d, fit = self.final_fit(chosen + [(cand, shape)])
        except DiagnosisError as exc:
            return float("nan"), str(exc)
        size = self.effect_size(d, fit, cand.name)
        if not (accepted and (self.plausible is not None or self.consistent is not None)):
            return size, None
        try:
            params = fitted_parameters(d, fit, cand.name)[0]
            reason = self.plausible(cand, params, shape) if self.plausible is not None else None
            if reason is None and self.consistent is not None:
                reason = self.consistent(cand, params, shape, size)
            return size, reason
        except DiagnosisError as exc:
            return size, str(exc)


@dataclass
class NullSettings(Record):
    """The null of the selection: bootstrap draws, family-wise level and method."""

    draws: int
    alpha: float
    method: str = ("wild bootstrap over training segments (Rademacher), max-statistic over the step's "
                   "candidates")


@dataclass
class BaselineInfo(Record):
    """The sim as is before any effect: robust loss (1 by definition), the flexible reference's robust loss, AIC
    and BIC with their distance to the best candidate, the null's settings and the robust target's cells."""

    robust_loss: float
    reference_robust_loss: float
    aic: float
    bic: float
    delta_aic: float
    delta_bic: float
    null: NullSettings
    robust_target: TargetSummary


@dataclass
class SelectionStep(Record):
    """One step of the forward selection: the candidate judged, its shape, robust losses before and after (shares
    of the sim's original robust loss), the gain with its null p and quantile, the flexible reference's loss, the
    explained share of the removable remainder, the RMS of the fitted contribution (N or W), whether it was
    accepted and why (``implausible``: the reason a fitted value is no plausible simulator setting)."""

    step: int
    effect: str
    shape: float | None
    robust_loss_before: float
    robust_loss_after: float
    relative_gain: float
    gain_of_original: float
    null_p: float
    null_quantile: float
    gain: list[float]
    reference_robust_loss: float
    explained_fraction: float
    accepted: bool
    size_rms: float
    implausible: str | None
    reason: str


def fitted_parameters(d: Design, fit: Fit, name: str) -> tuple[dict[str, float], dict[str, float], dict[str, str]]:
    """Fitted values, block-robust standard errors and units of the parameters of effect ``name`` in design ``d``."""
    se = np.sqrt(np.clip(np.diag(fit.cov), 0, None)) if fit.cov is not None else np.full(fit.X.size, np.nan)
    own = [i for i, o in enumerate(d.owner) if o == name]
    return ({d.names[i]: float(fit.X[i]) for i in own}, {d.names[i]: float(se[i]) for i in own},
            {d.names[i]: d.units[i] for i in own})


def _safe_sim_parameters(cand: CandidateEffect, params: dict, shape, model) -> dict | None:
    try:
        return cand.sim_parameters(params, shape, model)
    except (KeyError, ValueError, ZeroDivisionError):
        return None
