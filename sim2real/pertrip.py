"""Effects that differ between trips: one trip carries a payload, another runs the heater. Every accepted effect is
refitted with one size per trip (its regressors times the trip's indicator; the other accepted effects, and the
base when it is refitted jointly, stay shared), by least squares on the training rows of the *raw* residual (a
robust fit would pull a trip whose level is far from the others towards them), with cluster-robust standard
errors over the 60 s split segments (a trip's slow drifts — a heater warming up — are correlated over more than
the 10 s bootstrap blocks). Whether the sizes differ more than chance: the Wald test of equal sizes,
χ² = (C x)ᵀ (C V Cᵀ)⁻¹ (C x) with C the differences to the first trip, (k - 1) p degrees of freedom for k trips
and p parameters; the sizes differ when p_value <= alpha. Trips with fewer than ``min_rows`` training rows share
one size ("other trips")."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import stats

from .catalog import CandidateEffect
from .records import Record
from .selection import Design, Selector, design, fit_linear

OTHER_TRIPS = "other trips"


@dataclass
class TripSize(Record):
    """One trip's fitted parameters of an effect with their standard errors, and its training rows."""

    trip: str
    values: dict[str, float]
    std_errors: dict[str, float]
    n: int


@dataclass
class PerTripSizes(Record):
    """An effect's sizes per trip, their mean over the trips' training rows, and the Wald test of equal sizes
    (χ², degrees of freedom, p-value; ``differ``: p <= alpha)."""

    units: dict[str, str]
    sizes: list[TripSize]
    mean: dict[str, float]
    chi2: float
    dof: int
    p_value: float
    differ: bool


def _per_trip_design(sel: Selector, chosen: list[tuple[CandidateEffect, float | None]], name: str,
                     trips: np.ndarray, groups: list[str]) -> tuple[np.ndarray, list[tuple[str, str]]]:
    """The design with effect ``name``'s columns split by trip group (columns masked on braking rows as the final
    fit masks them; the base prepended when it is refitted jointly), and (group, parameter) of each split
    column."""
    d = design(chosen, sel.model, sel.cols)
    A = sel.fitted_columns(Design(d.A, d.names, d.units, d.owner))
    own = [i for i, o in enumerate(d.owner) if o == name]
    shared = [i for i, o in enumerate(d.owner) if o != name]
    blocks = [A[:, shared]] if shared else []
    labels: list[tuple[str, str]] = []
    for g in groups:
        ind = (trips == g) if g != OTHER_TRIPS else ~np.isin(trips, [x for x in groups if x != OTHER_TRIPS])
        blocks.append(A[:, own] * ind[:, None])
        labels += [(g, d.names[i]) for i in own]
    if sel.base_design is not None:
        blocks.insert(0, sel.base_design)
    return np.hstack(blocks), labels


def _groups(trips: np.ndarray, train: np.ndarray, min_rows: int) -> tuple[list[str], dict[str, int]]:
    """Trips with at least ``min_rows`` training rows, then "other trips" when some have fewer; rows per trip."""
    counts = {k: int(np.sum(train & (trips == k))) for k in dict.fromkeys(trips)}
    groups = [k for k, n in counts.items() if n >= min_rows]
    if any(n < min_rows for n in counts.values()):
        groups.append(OTHER_TRIPS)
    return groups, counts


def per_trip_sizes(sel: Selector, chosen: list[tuple[CandidateEffect, float | None]], name: str,
                   alpha: float = 0.01, min_rows: int = 200) -> PerTripSizes | None:
    """The per-trip sizes of accepted effect ``name`` (module doc); None with fewer than two trips."""
    trips = sel.table["trip"].to_numpy().astype(str)
    groups, counts = _groups(trips, sel.split.train, min_rows)
    if len([g for g in groups if g != OTHER_TRIPS]) < 2:
        return None
    A, labels = _per_trip_design(sel, chosen, name, trips, groups)
    fit = fit_linear(A, sel.residual, sel.split.train, robust=False, blocks=sel.split.segments)
    k = len(labels)
    x, V = fit.X[-k:], (fit.cov[-k:, -k:] if fit.cov is not None else np.full((k, k), np.nan))
    se = np.sqrt(np.clip(np.diag(V), 0, None))
    params = list(dict.fromkeys(p for _, p in labels))
    d = design([c for c in chosen if c[0].name == name], sel.model, sel.cols)
    sizes = []
    for g in groups:
        idx = [i for i, (gg, _) in enumerate(labels) if gg == g]
        n = counts[g] if g != OTHER_TRIPS else sum(v for key, v in counts.items() if key not in groups)
        sizes.append(TripSize(g, {labels[i][1]: float(x[i]) for i in idx},
                              {labels[i][1]: float(se[i]) for i in idx}, int(n)))
    w = np.array([s.n for s in sizes], dtype=float)
    w = w / max(w.sum(), 1.0)
    mean = {p: float(sum(wi * s.values[p] for wi, s in zip(w, sizes))) for p in params}
    chi2, dof, p_value = _wald_equal(x, V, len(groups), len(params))
    return PerTripSizes(dict(zip(d.names, d.units)), sizes, mean, chi2, dof, p_value, bool(p_value <= alpha))


def _wald_equal(x: np.ndarray, V: np.ndarray, n_groups: int, n_params: int) -> tuple[float, int, float]:
    """Wald test that every group's parameters equal the first group's: (χ², dof, p)."""
    dof = (n_groups - 1) * n_params
    C = np.zeros((dof, n_groups * n_params))
    for g in range(1, n_groups):
        for j in range(n_params):
            C[(g - 1) * n_params + j, g * n_params + j] = 1.0
            C[(g - 1) * n_params + j, j] = -1.0
    diff = C @ x
    cov = C @ V @ C.T
    if not np.all(np.isfinite(cov)):
        return float("nan"), dof, float("nan")
    chi2 = float(diff @ np.linalg.pinv(cov) @ diff)
    return chi2, dof, float(stats.chi2.sf(chi2, dof))
