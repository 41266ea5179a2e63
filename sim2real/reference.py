"""A flexible reference for the residual: an additive model over regime variables, r ≈ Σ_j f_j(bin_j(x_j)).

It knows no physics, so it can fit structure that no candidate effect explains. Two uses: (1) the explainable
part of a gap — a candidate that removes only a small share of what this reference removes is a partial fit,
not an identification; (2) localisation — the variance of each partial effect f_j says which regime variable
carries the unexplained residual, and its largest bin where. Bins are quantiles of the training data (numeric
variables) or categories; each f_j is a bin mean shrunk towards 0 with n/(n + shrinkage); fitted by backfitting.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from .errors import DiagnosisError
from .records import Record

# (column, kind): the regime variables the reference may use when the table has them
REFERENCE_VARIABLES: tuple[tuple[str, str], ...] = (
    ("speed", "numeric"), ("acceleration", "numeric"), ("gradient_angle", "numeric"),
    ("lateral_acceleration", "absolute"), ("time_since_start", "numeric"), ("mode", "category"),
    ("gear", "category"), ("ambient_temperature", "numeric"), ("payload", "numeric"),
)


@dataclass
class RegimeImportance(Record):
    """How much of the reference's fit one regime variable carries: the std of its partial effect [N] and its
    strongest bin with that bin's effect [N]."""

    column: str
    std: float
    strongest_bin: str
    strongest_effect: float


@dataclass
class AdditiveRegimeModel:
    """Additive binned model of a residual; ``fit`` then ``predict`` on any table with the same columns."""

    n_bins: int = 10
    shrinkage: float = 50.0
    iterations: int = 8
    variables: tuple[tuple[str, str], ...] = REFERENCE_VARIABLES
    edges: dict[str, np.ndarray] = field(default_factory=dict)
    categories: dict[str, np.ndarray] = field(default_factory=dict)
    effects: dict[str, np.ndarray] = field(default_factory=dict)
    intercept: float = 0.0

    def _index(self, table: pd.DataFrame, name: str, kind: str) -> np.ndarray:
        if kind == "category":
            cats = self.categories[name]
            col = table[name].to_numpy()
            idx = np.full(len(table), -1)
            for i, c in enumerate(cats):
                idx[col == c] = i
            return idx
        x = table[name].to_numpy(dtype=float)
        if kind == "absolute":
            x = np.abs(x)
        e = self.edges[name]
        idx = np.clip(np.searchsorted(e, x, side="right") - 1, 0, e.size - 2)
        idx[~np.isfinite(x)] = -1
        return idx

    def fit(self, table: pd.DataFrame, residual: np.ndarray) -> "AdditiveRegimeModel":
        r = np.asarray(residual, dtype=float)
        if r.shape[0] != len(table):
            raise DiagnosisError("reference model: residual and table differ in length")
        ok = np.isfinite(r)
        if ok.sum() < 10:
            raise DiagnosisError("reference model: fewer than 10 finite residual samples")
        t, r = table[ok], r[ok]
        self.variables = tuple(v for v in self.variables if v[0] in t.columns and self._learn_bins(t, *v))
        self._backfit(t, r)
        return self

    def _learn_bins(self, t: pd.DataFrame, name: str, kind: str) -> bool:
        """Categories or quantile edges of one variable from the training rows; False when it has too few
        distinct values to use."""
        if kind == "category":
            vals = t[name].to_numpy()
            cats = np.array(sorted({v for v in vals if v == v and v is not None}, key=str), dtype=object)
            if cats.size < 2:
                return False
            self.categories[name] = cats
            return True
        x = t[name].to_numpy(dtype=float)
        if kind == "absolute":
            x = np.abs(x)
        x = x[np.isfinite(x)]
        if x.size < 10 or np.ptp(x) == 0:
            return False
        e = np.unique(np.quantile(x, np.linspace(0, 1, self.n_bins + 1)))
        if e.size < 3:
            return False
        e[0], e[-1] = -np.inf, np.inf
        self.edges[name] = e
        return True

    def _backfit(self, t: pd.DataFrame, r: np.ndarray) -> None:
        """The partial effects f_j by backfitting: each bin mean of the partial residual shrunk towards 0 with
        n/(n + shrinkage) and centred (the intercept carries the mean)."""
        used = self.variables
        idx = {name: self._index(t, name, kind) for name, kind in used}
        nb = {name: (self.categories[name].size if kind == "category" else self.edges[name].size - 1)
              for name, kind in used}
        self.intercept = float(np.mean(r))
        f = {name: np.zeros(nb[name]) for name, _ in used}
        contrib = {name: np.zeros(r.size) for name, _ in used}
        total = np.full(r.size, self.intercept)
        for _ in range(self.iterations):
            for name, _k in used:
                i = idx[name]
                partial = r - (total - contrib[name])
                good = i >= 0
                sums = np.bincount(i[good], weights=partial[good], minlength=nb[name])
                counts = np.bincount(i[good], minlength=nb[name]).astype(float)
                new = sums / (counts + self.shrinkage)
                new -= np.sum(new * counts) / max(counts.sum(), 1.0)   # centre: the intercept carries the mean
                f[name] = new
                c = np.where(good, new[np.clip(i, 0, None)], 0.0)
                total += c - contrib[name]
                contrib[name] = c
        self.effects = f

    def predict(self, table: pd.DataFrame) -> np.ndarray:
        out = np.full(len(table), self.intercept)
        for name, kind in self.variables:
            i = self._index(table, name, kind)
            out += np.where(i >= 0, self.effects[name][np.clip(i, 0, None)], 0.0)
        return out

    def importance(self, table: pd.DataFrame) -> list[RegimeImportance]:
        """Per variable: the std of its partial effect over ``table`` [N] and its strongest bin, largest first."""
        rows: list[RegimeImportance] = []
        for name, kind in self.variables:
            i = self._index(table, name, kind)
            c = np.where(i >= 0, self.effects[name][np.clip(i, 0, None)], 0.0)
            j = int(np.argmax(np.abs(self.effects[name])))
            if kind == "category":
                where = str(self.categories[name][j])
            else:
                e = self.edges[name]
                where = f"[{e[j]:.4g}, {e[j + 1]:.4g})"
            rows.append(RegimeImportance(name, float(np.std(c)), where, float(self.effects[name][j])))
        rows.sort(key=lambda d: -d.std)
        return rows
