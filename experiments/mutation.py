"""Mutation score of the pure-Python cores: mutmut (pinned dev dependency) run on one module at a time against the
tests that target it, the score printed per module.

Each module is staged on its own: the installed package layout (``src/roadload/...``, built from pyproject's
package-dir mapping, package data included) plus the test folder, with a ``[tool.mutmut]`` table that mutates
that one file and selects its targeted tests. ``PYTHONPATH`` points at the mutated tree, so a test that starts a
subprocess runs the mutant too. The score counts killed mutants (a failing test, a timeout or a crash) over all
mutants minus the known equivalent ones (:data:`EQUIVALENT`: same behaviour, no test can tell them apart); a
surviving mutant or one that no selected test reaches counts against it.

    python scripts/mutation_score.py                              # every module, one after the other
    python scripts/mutation_score.py --module core/road_load.py --survivors
    python scripts/mutation_score.py --quick                      # CI: one small module, its own tests
    python scripts/mutation_score.py --module core/trip.py --rerun  # only the previous run's live mutants again
    python scripts/mutation_score.py --module core/trip.py --resume  # continue a stopped run, keep its verdicts
    python scripts/mutation_score.py --module envs/sensors.py --tests-from a7b604b^ --sample 150 --seed 0

``--tests-from COMMIT`` scores against the ``tests/`` tree of that commit (and, unless ``--tests`` is given, the
module's test selection listed in that commit's ``MODULES``): the "before" score of tests added later.
``--sample N --seed S`` tests a seeded simple random sample of N of the module's mutants; the score is then printed
with its 95 % Wilson interval. With ``--resume`` and the same seed, a stopped sampled run continues its own sample
(its verdicts stand), and a larger N grows the sample by a seeded sample of the mutants not yet in it, so a sample
can be sized to the CPU a run gets: ``--sample 40 --seed 0 --resume``, then ``--sample 160 --seed 0 --resume``.
"""

from __future__ import annotations

import argparse
import ast
import json
import math
import os
import random
import shutil
import subprocess
import sys
import tempfile
import time
import tomllib
from collections.abc import Mapping
from dataclasses import asdict, dataclass, field
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]

# module (repository path) -> the test files (or test ids) that target it (fast ones: every mutant reruns the tests
# that reach it)
MODULES: dict[str, tuple[str, ...]] = {
    "core/road_load.py": ("tests/core/test_road_load.py", "tests/core/test_road_load_contracts.py",
                          "tests/envs/test_physics.py"),
    "core/trip.py": ("tests/core/test_trip.py", "tests/core/test_trip_mutants.py",
                     "tests/core/test_trip_files.py::test_a_format_1_file_loads_and_converts",
                     "tests/core/test_trip_files.py::test_exact_precision_is_bit_for_bit_and_keeps_dtypes"),
    "core/trip_schema.py": ("tests/core/test_trip_schema.py", "tests/fuzz/test_fuzz_files.py",
                            "tests/envs/test_streaming.py"),
    "sim2real/stats.py": ("tests/sim2real/test_core.py", "tests/sim2real/test_stats_values.py"),
    "sim2real/selection.py": ("tests/sim2real/test_selection_mutants.py",
                              "tests/sim2real/test_selection_ranking_mutants.py", "tests/sim2real/test_core.py"),
    "sim2real/floor.py": ("tests/sim2real/test_floor_fit.py", "tests/sim2real/test_floor.py"),
    "experiments/time_matching.py": ("tests/experiments/test_time_matching.py",
                                     "tests/experiments/test_time_matching_search.py"),
    "controllers/mpc.py": ("tests/controllers/test_mpc_mutants.py",
                           "tests/controllers/test_mpc_plan_report_mutants.py"),
    "controllers/mpc_controller.py": ("tests/controllers/test_mpc_controller_mutants.py",),
    "envs/sensors.py": ("tests/envs/test_sensors_mutants.py", "tests/envs/test_sensor_noise.py"),
}

# module -> {"function: removed line -> added line": why no test can tell the mutant from the original}
_NO_UNITS = ("TripPayload's fields carry no unit and it allows extra keys, so format_errors words every error the "
             "same with or without the model")
_RAISE = 'raise TripMetadataError(f"{{path}}: {{format_errors(exc, {})}}") from None'
_PAYLOAD = "x_parse_trip_payload: " + _RAISE.format("TripPayload, root='metadata'") + " -> "
_XP = "numpy's sin and cos of a CasADi expression call the expression's own, so xp=np gives the same force"
_MPC_FLOAT = "float() converts the element it picks anyway"
_MPC_CTL = "xǁMpcControllerǁ"
_CAP_LINE = "cap[max(k, 0):min(k + 2, n + 1)] = st.stop_speed"
_SEG0 = "seg0 = np.where(s0 + SEGMENT0_FRACTIONS * ds {} stop - 1e-9, np.minimum(seg0, st.stop_speed), seg0)"
_STOPS = "stops = np.array([x for x in self._unserved if s[0] - 1.0 <= x <= s[-1]], {})"
_UNSERVED = "self._unserved = list(np.sort(np.asarray(road.stops, {})))"
_CRUISE = 'elif self.mode == "cruise" or self.plan is None:'
_NO_PLAN_CRUISE = ("where this branch is reached the mode is 'cruise' exactly when there is no plan: a fallback to "
                   "cruise control drops the plan, a solve that gives one sets 'mpc', the brake modes return earlier")
MPC_EQUIVALENT: dict[str, str] = {
    "xǁOcpSolverǁ_force_limit: if residual > 0: -> if residual >= 0:":
        "diagnose calls it only for a force-balance residual larger than 1e-4 kN in size, never 0",
    "xǁOcpSolverǁ_force_limit: limit = min(float(np.asarray(en.max_traction_force(None, preview.ratio), float)[k]), "
    "-> limit = min(float(np.asarray(en.max_traction_force(None, preview.ratio), None)[k]),": _MPC_FLOAT,
    "xǁOcpSolverǁ_force_limit: limit = min(float(np.asarray(en.max_traction_force(None, preview.ratio), float)[k]), "
    "-> limit = min(float(np.asarray(en.max_traction_force(None, preview.ratio), )[k]),": _MPC_FLOAT,
    "xǁOcpSolverǁ_force_limit: regen = np.broadcast_to(np.asarray(en.max_regen_force(preview.ratio), float), "
    "np.shape(preview.ratio)) -> regen = np.broadcast_to(np.asarray(en.max_regen_force(preview.ratio), None), "
    "np.shape(preview.ratio))": _MPC_FLOAT,
    "xǁOcpSolverǁ_force_limit: regen = np.broadcast_to(np.asarray(en.max_regen_force(preview.ratio), float), "
    "np.shape(preview.ratio)) -> regen = np.broadcast_to(np.asarray(en.max_regen_force(preview.ratio), ), "
    "np.shape(preview.ratio))": _MPC_FLOAT,
}
_QP_A = "A = sp.csc_matrix((adata, self._a_rows, self._a_indptr), {})"
_QP_STATUS = 'status, iters, ok = "{}", 0, False'
_OSQP_DEFAULT = "OSQP's default (osqp 1.x: warm_starting on, max_iter 4000)"
MPC_EQUIVALENT.update({
    "xǁOcpSolverǁ_solve_qp: " + _QP_A.format("shape=(self._ng + self._nx, self._nx)") + " -> "
    + _QP_A.format("shape=None"): "the last column's identity row sets the same shape",
    "xǁOcpSolverǁ_solve_qp: " + _QP_A.format("shape=(self._ng + self._nx, self._nx)") + " -> " + _QP_A.format(""):
        "the last column's identity row sets the same shape",
    "xǁOcpSolverǁ_solve_qp: self._osqp.setup(P, grad, A, lo, hi, verbose=False, warm_starting=True, "
    "polishing=False, -> self._osqp.setup(P, grad, A, lo, hi, verbose=False, polishing=False,": _OSQP_DEFAULT,
    "xǁOcpSolverǁ_solve_qp: max_iter=4000, adaptive_rho=True, rho=3.0) -> adaptive_rho=True, rho=3.0)":
        _OSQP_DEFAULT,
    "xǁOcpSolverǁ_solve_qp: " + _QP_STATUS.format("not run") + " -> " + _QP_STATUS.format("XXnot runXX"):
        "the loop runs at least once and sets the status",
    "xǁOcpSolverǁ_solve_qp: " + _QP_STATUS.format("not run") + " -> " + _QP_STATUS.format("NOT RUN"):
        "the loop runs at least once and sets the status",
    "xǁOcpSolverǁ_solve_qp: lo = np.where(np.isfinite(lo), lo, -1e20) -> lo = np.where(np.isfinite(lo), lo, "
    "-1e+20)": "the same number written another way",
})
_IPOPT_STATS = "CasADi's IPOPT stats always hold return_status, success and iter_count: the default is never used"
_STATUS_GET = 'status = str(stats.get("return_status", "{}"))'
_OK_GET = 'ok = bool(stats.get("success"{})) or status == "Solved_To_Acceptable_Level"'
for _variant in ("XXunknownXX", "UNKNOWN"):
    MPC_EQUIVALENT["xǁOcpSolverǁ_solve_ipopt: " + _STATUS_GET.format("unknown") + " -> "
                   + _STATUS_GET.format(_variant)] = _IPOPT_STATS
for _variant in (", ", ", None", ", True"):
    MPC_EQUIVALENT["xǁOcpSolverǁ_solve_ipopt: " + _OK_GET.format(", False") + " -> "
                   + _OK_GET.format(_variant)] = _IPOPT_STATS
_NUMERIC = "the preview's arrays hold numbers: a float array either way"
_RAISED0 = "raised[0] = {}  # node 0 is the current state, not a decision"
_CHECK_DS = "if preview.ds is not None and not np.all(np.asarray(preview.ds, {}) > 0):"
_JERK_IF = "if a_prev - step > st.accel_max + 1e-9 or a_prev + step {} -st.decel_max - 1e-9:"
_BACKWARD = "for k in range(n - 1, {}, -1):  # backward pass: comfortable deceleration before caps"
_RELAXED = "raised = self.reachable_cap(v0, preview, a_prev) {} self.planning_cap(preview) + 1e-9"
MPC_EQUIVALENT.update({
    "xǁOcpSolverǁ_check: " + _CHECK_DS.format("float") + " -> " + _CHECK_DS.format("None"): _NUMERIC,
    "xǁOcpSolverǁ_check: arr = np.asarray(arr, float) -> arr = np.asarray(arr, None)": _NUMERIC,
    "xǁOcpSolverǁrelaxations: s = np.asarray(preview.s, float) -> s = np.asarray(preview.s, None)": _NUMERIC,
    "xǁOcpSolverǁrelaxations: s = np.asarray(preview.s, float) -> s = np.asarray(preview.s, )": _NUMERIC,
    "xǁOcpSolverǁrelaxations: actual = np.asarray(preview.speed_cap, float) -> "
    "actual = np.asarray(preview.speed_cap, )": _NUMERIC,
    "xǁOcpSolverǁrelaxations: actual = np.asarray(preview.speed_cap, float) -> "
    "actual = np.asarray(preview.speed_cap, None)": _NUMERIC,
    'xǁOcpSolverǁ_solve_ipopt: plan = self._plan_from_x(x, preview, ok, status, elapsed, int(stats.get("iter_count", '
    '-1)), -> plan = self._plan_from_x(x, preview, ok, status, elapsed, int(stats.get("iter_count", )),':
        _IPOPT_STATS,
    "xǁOcpSolverǁcontradictions: " + _JERK_IF.format("<") + " -> " + _JERK_IF.format("<="):
        "equal only if a_prev + step is exactly -decel_max - 1e-9",
    "xǁOcpSolverǁcontradictions: bound = st.accel_max if a_prev > 0 else -st.decel_max -> "
    "bound = st.accel_max if a_prev > 1 else -st.decel_max":
        "a contradiction on the acceleration side needs a_prev > accel_max + step > 1; on the braking side a_prev < 0",
    "xǁOcpSolverǁinitial_guess: " + _BACKWARD.format("-1") + " -> " + _BACKWARD.format("-2"):
        "the extra pass k = -1 takes the else branch (v[-1] = v[-1])",
    "xǁOcpSolverǁrelaxations: " + _RAISED0.format("False") + " -> " + _RAISED0.format("None"):
        "None stored in a bool array is False",
    "xǁOcpSolverǁrelaxations: " + _RAISED0.format("False") + " -> " + _RAISED0.format("True"):
        "the runs are searched from node 1: node 0 only decides the early return, and with no other node raised the "
        "search finds none",
    "xǁOcpSolverǁrelaxed_nodes: " + _RELAXED.format(">") + " -> " + _RELAXED.format(">="):
        "a node not raised has its planning cap exactly, a raised one 0.1 m/s more: never within 1e-9",
})
_HEADWIND = "headwind = np.full(n, params.headwind) if preview.headwind is None else np.asarray(preview.headwind, {})"
_CROSSWIND = "crosswind = np.zeros(n) if preview.crosswind is None else np.asarray(preview.crosswind, {})"
_PLANNING = "return np.maximum(np.asarray(preview.speed_cap, {}) - st.speed_margin, st.speed_floor)"
for _source, _fn in ((_HEADWIND, "_params"), (_CROSSWIND, "_params"), (_PLANNING, "planning_cap")):
    for _variant in ("None", ""):
        MPC_EQUIVALENT[f"xǁOcpSolverǁ{_fn}: " + _source.format("float") + " -> " + _source.format(_variant)] = _NUMERIC
_JNZ = 'jnz = np.asarray(jac.nonzeros()) if hasattr(jac, "nonzeros") else np.asarray({}).ravel()'
MPC_EQUIVALENT["xǁOcpSolverǁ_qp_matrices: " + _JNZ.format("jac") + " -> " + _JNZ.format("None")] = \
    "the QP data function is a CasADi Function: its Jacobian output is a DM, which has nonzeros() (dead branch)"
_ADAPTIVE = '"acceptable_tol": 1e-4, "acceptable_iter": 5, "mu_strategy": "{}",'
_A_INDPTR = "self._a_indptr = np.concatenate([[0], np.cumsum(np.bincount(cols_a, {}))])"
MPC_EQUIVALENT.update({
    "xǁOcpSolverǁ_build: " + _ADAPTIVE.format("adaptive") + " -> " + _ADAPTIVE.format("ADAPTIVE"):
        "IPOPT reads option values in any case",
    **{"xǁOcpSolverǁ_build: " + _A_INDPTR.format("minlength=self._nx") + " -> " + _A_INDPTR.format(v):
       "every column of A holds its identity row, so the count already has one entry per column"
       for v in ("", "minlength=None")},
    "xǁOcpSolverǁ_build: self._a_cols = np.array(cols_a, dtype=int) -> self._a_cols = np.array(cols_a, )":
        "a list of Python ints is an int array without the dtype",
    "xǁOcpSolverǁdiagnose: g = np.asarray(self._g_fun(plan.x, self._params(a_prev, preview, params, time_weight)))"
    ".ravel() -> g = np.asarray(self._g_fun(plan.x, self._params(a_prev, preview, params, ))).ravel()":
        "the constraint vector does not depend on the time weight (only the objective does)",
})
_ITER = 'plan = self._plan_from_x(x, preview, ok, status, elapsed, int(stats.get("iter_count", {})),'
_SHIFT_S = "new = self.settings.ds * np.arange(self.n + 1) + s0 if s is None else np.asarray(s, {})"
MPC_EQUIVALENT.update({
    "xǁOcpSolverǁ_solve_ipopt: " + _ITER.format("-1") + " -> " + _ITER.format("None"): _IPOPT_STATS,
    **{"xǁOcpSolverǁshift: " + _SHIFT_S.format("float") + " -> " + _SHIFT_S.format(v): _NUMERIC for v in ("None", "")},
})
MPC_EQUIVALENT["xǁOcpSolverǁsolve: found += self.diagnose(plan, a_prev, preview, params, time_weight) -> "
               "found += self.diagnose(plan, a_prev, preview, params, )"] = \
    "the constraint vector the diagnosis reads does not depend on the time weight (only the objective does)"
# CasADi symbol and function names: labels only (no lookup by name), so renaming one changes nothing
_NAMED = [("_formulate", f'{var} = ca.SX.sym("{name}"{rest})') for var, name, rest in (
    ("E", "E", ", n + 1"), ("ft", "Ft", ", n"), ("fr", "Fr", ", n"), ("fb", "Fb", ", n"), ("a_prev", "a_prev", ""),
    ("grade", "grade", ", n"), ("curv", "curv", ", n"), ("ratio", "ratio", ", n"),
    ("fp", "fp", ", len(RoadLoadParameters.FIELDS)"), ("lam", "lam", ""), ("headwind", "headwind", ", n"),
    ("crosswind", "crosswind", ", n"), ("yaw_drag", "yaw_drag", ""))]
_NAMED += [("_formulate", 'ds = ca.SX.sym("ds", n)  # segment lengths [m] (the MPC: uniform; the full-route '
                          'optimum: nodes at stops)'),
           ("_build", 'self._energy_fun = ca.Function("energy", [x, p], [energy * 1000.0])'),
           ("_build", 'self._g_fun = ca.Function("constraints", [x, p], [g])  # diagnosis of a solve that did not '
                      'converge'),
           ("_build", 'self._cold = ca.nlpsol("mpc_cold", "ipopt", self._nlp, opts)'),
           ("_build", 'self._warm = ca.nlpsol("mpc_warm", "ipopt", self._nlp, warm)'),
           ("_build", 'lam_g = ca.SX.sym("lam_g", self._ng)'),
           ("_build", 'self._qp_fun = ca.Function("qp_data", [x, p, lam_g],')]
for _fn, _named in _NAMED:
    _label = _named.split('"')[1]
    for _new in {f"XX{_label}XX", _label.upper(), _label.lower()} - {_label}:
        MPC_EQUIVALENT[f"xǁOcpSolverǁ{_fn}: {_named} -> " + _named.replace(f'"{_label}"', f'"{_new}"', 1)] = \
            "a CasADi symbol or function name is a label: nothing looks it up"
_SEGLEN = "return np.full(self.n, self.settings.ds) if preview.ds is None else np.asarray(preview.ds, {})"
MPC_EQUIVALENT.update({
    "xǁOcpSolverǁ__init__: self._qp_x = None -> self._qp_x = \"\"": "nothing reads _qp_x",
    "xǁOcpSolverǁ_braking: speed, accel = np.empty(n_nodes), np.empty(max(n_nodes - 1, 0)) -> "
    "speed, accel = np.empty(n_nodes), np.empty(max(n_nodes - 1, 1))":
        "the grid has n_nodes >= 3 nodes (n_nodes >= 2 segments): the floor never applies",
    'xǁOcpSolverǁ_build: "warm_start_slack_bound_push": 1e-7, "mu_strategy": "monotone"} -> '
    '"warm_start_slack_bound_push": 1e-7, "mu_strategy": "MONOTONE"}': "IPOPT reads option values in any case",
    "xǁOcpSolverǁsegment_lengths: " + _SEGLEN.format("float") + " -> " + _SEGLEN.format("None"): _NUMERIC,
    "xǁOcpSolverǁsegment_lengths: " + _SEGLEN.format("float") + " -> " + _SEGLEN.format(""): _NUMERIC,
})
MPC_CONTROLLER_EQUIVALENT: dict[str, str] = {
    _MPC_CTL + "_multistart: ref = self.plan if self.plan is not None else plan -> "
    "ref = self.plan if (self.plan is not None) or True else plan":
        "_solve runs the multistart only when there is a previous plan, so ref is always that plan",
    _MPC_CTL + "serve_stop: self._unserved = [x for x in self._unserved if abs(x - stop) > 1e-9] -> "
    "self._unserved = [x for x in self._unserved if abs(x - stop) >= 1e-9]":
        "the served stop is in the list exactly (distance 0); no other stop lies exactly 1e-9 m from it",
    _MPC_CTL + '_replan: if self.mode != "mpc": -> if self.mode != "XXmpcXX":':
        "the mode becomes 'mpc' either way: setting it when it already is changes nothing",
    _MPC_CTL + '_replan: if self.mode != "mpc": -> if self.mode != "MPC":':
        "the mode becomes 'mpc' either way: setting it when it already is changes nothing",
    _MPC_CTL + "_solve: plan, ok = None, False -> plan, ok = None, True":
        "ok is read only together with a plan (_replan: ok and plan is not None)",
    _MPC_CTL + f"wheel_force: {_CRUISE} -> " + _CRUISE.replace(" or ", " and "): _NO_PLAN_CRUISE,
    _MPC_CTL + f"wheel_force: {_CRUISE} -> " + _CRUISE.replace('"cruise"', '"XXcruiseXX"'): _NO_PLAN_CRUISE,
    _MPC_CTL + f"wheel_force: {_CRUISE} -> " + _CRUISE.replace('"cruise"', '"CRUISE"'): _NO_PLAN_CRUISE,
    _MPC_CTL + "_brake_target_of: return max(hard, key=lambda v: (obs.v ** 2 - v.limit ** 2) / (2.0 * (v.position "
    "- obs.s))) -> return max(hard, key=lambda v: (obs.v ** 2 - v.limit ** 2) / (3.0 * (v.position - obs.s)))":
        "every key scaled by the same positive factor: the same maximum",
    _MPC_CTL + "preview: cap = np.array([self._fine_cap[a:max(b, a + 1)].min() for a, b in zip(lo, hi)]) -> "
    "cap = np.array([self._fine_cap[a:max(b, a + 2)].min() for a, b in zip(lo, hi)])":
        "from s0 >= 0 every node's window holds 11 or more samples of the 2 m grid (which runs a horizon and two "
        "segments past the road end), so max(b, a + 1) is b",
    _MPC_CTL + f"preview: {_CAP_LINE} -> " + _CAP_LINE.replace("n + 1", "n + 2"):
        "a slice that ends past the array's end is the same slice",
    _MPC_CTL + "preview: " + _SEG0.format(">=") + " -> " + _SEG0.format(">"):
        "a sample at the line lies 1e-9 m above stop - 1e-9 either way",
    _MPC_CTL + "preview: seg0 = np.where(inside >= stop - 1e-9, np.minimum(seg0, st.stop_speed), seg0) -> "
    "seg0 = np.where(inside > stop - 1e-9, np.minimum(seg0, st.stop_speed), seg0)":
        "a sampled point of segment 0 lies exactly 1e-9 m before a stop line only by coincidence of the grid",
    _MPC_CTL + "preview: v_guess = np.full(n, max(v0, st.speed_floor)) -> v_guess = np.full(n, None)":
        "the guessed speed only picks an EV's single ratio (an ICE's bound takes its lowest gear): any speed gives "
        "the same ratio",
    _MPC_CTL + 'preview: ratio = np.full(n, en.gear_ratios[0]) if en.kind == "ice" else '
    'en.ratio_for_speed(v_guess)  # ICE: lowest -> ratio = np.full(n, en.gear_ratios[0]) if (en.kind == "ice") '
    'or True else en.ratio_for_speed(v_guess)  # ICE: lowest': "an EV has one ratio, gear_ratios[0]",
    _MPC_CTL + "preview: " + _STOPS.format("dtype=float") + " -> " + _STOPS.format("dtype=None"):
        "stop positions are floats: the array is float anyway",
    _MPC_CTL + "preview: " + _STOPS.format("dtype=float") + " -> " + _STOPS.format(""):
        "stop positions are floats: the array is float anyway",
    _MPC_CTL + "preview: mid = np.minimum(s[:-1] + 0.5 * ds if segment_lengths is None else 0.5 * (s[:-1] + "
    "s[1:]), road.length) -> mid = np.minimum(s[:-1] + 0.5 * ds if (segment_lengths is None) and False else "
    "0.5 * (s[:-1] + s[1:]), road.length)": "on a uniform grid both give each segment's midpoint",
    _MPC_CTL + 'gear_request: shifting = obs.sample.get("clutch", 1.0) < 1.0 or (self._requested is not None and '
    'obs.gear != self._requested) -> shifting = obs.sample.get("clutch", 2.0) < 1.0 or (self._requested is not '
    'None and obs.gear != self._requested)': "a missing clutch reading counts as closed: any default >= 1 does",
    _MPC_CTL + "wheel_force: self.cruise.restart(obs.v) -> self.cruise.restart(None)":
        "cruise control's force, called next in the same step, starts a missing reference at the same measured "
        "speed (the integral is cleared either way)",
    _MPC_CTL + "reset: self._next_replan = -np.inf -> self._next_replan = +np.inf":
        "the first step solves anyway (no plan in mpc mode) and sets the next re-plan time from then on",
    _MPC_CTL + "reset: " + _UNSERVED.format("dtype=float") + " -> " + _UNSERVED.format("dtype=None"):
        "RoadProfile stores its stops as a float array",
    _MPC_CTL + "reset: " + _UNSERVED.format("dtype=float") + " -> " + _UNSERVED.format(""):
        "RoadProfile stores its stops as a float array",
    _MPC_CTL + "reset: self._brake_target: ConstraintViolation | None = None  # the stop / cap the fallback brake is "
    'meeting -> self._brake_target: ConstraintViolation | None = ""  # the stop / cap the fallback brake is meeting':
        "nothing reads the brake target before the first re-plan sets it",
    _MPC_CTL + "time_weight: if previous is not None and obs.s > previous[1]:  # interpolate the crossing of "
    "``start`` -> if previous is not None and obs.s >= previous[1]:  # interpolate the crossing of ``start``":
        "the branch runs at the crossing, where the previous position lies before start and the current one at or "
        "past it: never equal",
}
_SHARED = ("this branch is taken only when measured and truth share one time base (or there is no truth), which the "
           "writer also finds on its own; both ways write the same file")
_CHUNKS = "iter_trip_chunks reads 360_000 rows a chunk by default"
_WITH_TIME = 'with TripWriter(out, payload["units"], truth_units, precision, res, shared_time=True) as writer:'
_V2 = ('shared = payload["version"] >= 2 and (payload["version"] >= 4 and payload.get("time_base") == "shared" -> '
       'shared = payload["version"] {} and (payload["version"] >= 4 and payload.get("time_base") == "shared"')
_S = "xǁSensorModelǁ"
_NOISE = ("add[:] = self.bias[j] + self.noise[j] * g.standard_normal(CHUNK) if self.noise[j] > 0 else self.bias[j]"
          " -> add[:] = self.bias[j] + self.noise[j] * g.standard_normal(CHUNK) if {} else self.bias[j]")
_ZERO_NOISE = "with noise_std 0 the drawn noise is multiplied by 0: the channel reads its bias either way"
_FILLED = "EffectsConfig fills every parameter with its default, so the key is always there"
_BOOL_LIST = "a list of bools is a bool array without the dtype; with no names the explicit list refused earlier"
_NAN = "assigning None to a float array stores NaN"
_CLOSED = "a probability of drawing exactly the threshold is 2^-53"


def _get_default(function: str, line: str, key: str, default: str, new: tuple[str, ...]) -> dict[str, str]:
    """EQUIVALENT entries for every mutation of the default of a ``p.get(key, default)`` on one line."""
    old = f'p.get("{key}", {default})'
    return {f"{_S}{function}: {line} -> {line.replace(old, f'p.get({chr(34)}{key}{chr(34)}, {n})')}": _FILLED
            for n in new}


_COL = "self._col = np.array([_SIMPLE.get(n, special.get(n, 0)) for n in self.names], dtype=np.int64)"
_GROUP = 'self.{0}_on = self._group(str(p["channels"]), str(p.get("channel", "")), "sensor_{0}s")'
_SENSOR_EQUIVALENT: dict[str, str] = {
    **_get_default("_dropout_setup", _GROUP.format("dropout"), "channel", '""', ("None", "", '"XXXX"')),
    **_get_default("_outlier_setup", _GROUP.format("outlier"), "channel", '""', ("None", "", '"XXXX"')),
    **_get_default("_dropout_setup", 'if self.missing_mode and p.get("channel", ""):', "channel", '""',
                   ("None", "", '"XXXX"')),
    **_get_default("_outlier_setup", 'burst = float(p.get("burst_length", 1.0))', "burst_length", "1.0",
                   ("None", "", "2.0")),
    f"{_S}_channel_errors: " + _NOISE.format("self.noise[j] >= 0"): _ZERO_NOISE,
    f"{_S}_channel_errors: " + _NOISE.format("(self.noise[j] > 0) or True"): _ZERO_NOISE,
    f"{_S}_channel_errors: if self.burst_length > 1: -> if self.burst_length >= 1:":
        "bursts of one sample draw the same numbers in the same order as isolated outliers, and a one-sample burst "
        "of the chunk before never reaches this one",
    f"{_S}_dropped: if b > a: -> if b >= a:": "drop[a:a] = True sets nothing",
    f"{_S}_dropout_runs: starts = c * CHUNK + g.integers(0, CHUNK, size=n) -> "
    "starts = c * CHUNK + g.integers(CHUNK, size=n)": "integers(high) is integers(0, high), the same draws",
    f'{_S}_group: def _group(self, which: str, explicit: str = "", effect: str = "") -> np.ndarray: -> '
    'def _group(self, which: str, explicit: str = "XXXX", effect: str = "") -> np.ndarray:':
        "both callers pass explicit",
    f'{_S}_group: def _group(self, which: str, explicit: str = "", effect: str = "") -> np.ndarray: -> '
    'def _group(self, which: str, explicit: str = "", effect: str = "XXXX") -> np.ndarray:': "both callers pass effect",
    f"{_S}_group: return np.array([n in wanted for n in self.names], dtype=bool) -> "
    "return np.array([n in wanted for n in self.names], dtype=None)": _BOOL_LIST,
    f"{_S}_group: return np.array([n in wanted for n in self.names], dtype=bool) -> "
    "return np.array([n in wanted for n in self.names], )": _BOOL_LIST,
    f"{_S}_outlier_bursts: signs = np.where(go.random(starts.size) < 0.5, -1.0, 1.0) -> "
    "signs = np.where(go.random(starts.size) <= 0.5, -1.0, 1.0)": _CLOSED,
    f'{_S}_outlier_bursts: starts = np.flatnonzero(go.random(CHUNK) < float(self.outliers["rate"])) -> '
    'starts = np.flatnonzero(go.random(CHUNK) <= float(self.outliers["rate"]))': _CLOSED,
    f'{_S}_true: raise SensorConfigError(f"no sensor model for channel {{name!r}}")  # pragma: no cover - checked in '
    '__init__ -> raise SensorConfigError(None)  # pragma: no cover - checked in __init__':
        "unreachable: __init__ refuses every channel _true has no relation for",
    f"{_S}sample: val[:] = np.nan -> val[:] = None": _NAN,
    f"{_S}measure: val[np.concatenate([p[1][j] for p in perturb if p[1] is not None])[lo:lo + n_meas]] = np.nan -> "
    "val[np.concatenate([p[1][j] for p in perturb if p[1] is not None])[lo:lo + n_meas]] = None": _NAN,
    f"{_S}measure: c1 = (i0 + n_meas + CHUNK - 1) // CHUNK if n_meas else c0 -> "
    "c1 = (i0 + n_meas + CHUNK - 1) // CHUNK if (n_meas) or True else c0":
        "with no samples the perturbation chunks are drawn but sliced to nothing",
    f"{_S}_channel_errors: if b > a: -> if b >= a:": "add[a:a] += x adds nothing",
    f'{_S}_channel_errors: idx = np.flatnonzero(u < float(self.outliers["rate"])) -> '
    'idx = np.flatnonzero(u <= float(self.outliers["rate"]))': _CLOSED,
    f"{_S}_channel_errors: signs = np.where(go.random(idx.size) < 0.5, -1.0, 1.0) -> "
    "signs = np.where(go.random(idx.size) <= 0.5, -1.0, 1.0)": _CLOSED,
    f"{_S}_chunk: self._cache.popitem(last=False) -> self._cache.popitem(last=None)": "None is false as last=False",
    f"{_S}__init__: if abs(step - round(step)) > 1e-9 or round(step) < 1: -> "
    "if abs(step - round(step)) >= 1e-9 or round(step) < 1:": "no sample rate in [1, 1000] Hz is 1e-9 off a divisor",
    f"{_S}__init__: self.vehicle = vehicle -> self.vehicle = None": "kept for the reader; nothing reads it",
    **{f"{_S}__init__: self._steer_{a} = np.asarray(st.{f}, float) -> self._steer_{a} = np.asarray(st.{f}, {d})":
       "the validated steering table is a list of floats: a float array without the dtype"
       for a, f in (("x", "wheel_angle"), ("y", "steering_wheel_angle")) for d in ("None", "")},
    **{f"{_S}__init__: {_COL} -> {_COL.replace('special.get(n, 0)', f'special.get(n, {d})')}":
       "every supported channel is in _SIMPLE or in the special table, so the default is never used"
       for d in ("", "1", "None")},
    f"{_S}sample: val[nan[:, ii]] = np.nan -> val[nan[:, ii]] = None": _NAN,
}
_SEL = "xǁSelectorǁ"
_RATIO = ("the removable part is loss_before - min(reference, loss_before - gain) >= gain, so where it is > 0 the "
          "ratio never exceeds 1: the cap at 1 never applies")
_STEP_FRAC = "frac = float(min(gain / explainable, {})) if explainable > 0 else 0.0"
_ALONE_FRAC = "frac = float(np.clip(gain / explainable, -np.inf, {})) if explainable > 0 else 0.0"
_TIME = 't = table["t"].to_numpy({})'
_CACHE = "cache = self.__dict__.setdefault({}, {{}})"
_BRAKE = "brake = np.array([get_candidate(o).is_brake for o in d.owner], {})"
_MASK = 'mask = np.array([o != "base" and not get_candidate(o).is_brake for o in d.owner], {})'
_RESHAPE = "B = np.asarray(self.base_design, dtype=float).reshape(len(self.table), {})"
SELECTION_EQUIVALENT: dict[str, str] = {
    f"{_SEL}_judge_step: {_STEP_FRAC.format('1.0')} -> {_STEP_FRAC.format('2.0')}": _RATIO,
    **{f"{_SEL}_judge_alone: {_ALONE_FRAC.format('1.0')} -> {_ALONE_FRAC.format(v)}": _RATIO
       for v in ("2.0", "None")},
    **{f"x_make_split: {_TIME.format('dtype=float')} -> {_TIME.format(v)}":
       "block_ids, the time's only reader, converts it to float itself" for v in ("dtype=None", "")},
    **{f"{_SEL}_reference_loss: {_CACHE.format(chr(34) + '_ref_cache' + chr(34))} -> {_CACHE.format(v)}":
       "the cache's key in the instance's dict is a name only this method reads" for v in ("None", '"XX_ref_cacheXX"',
                                                                                          '"_REF_CACHE"')},
    **{f"{_SEL}final_fit: {_BRAKE.format('dtype=bool')} -> {_BRAKE.format(v)}":
       "a list of bools is a bool array without the dtype, and it is never empty (at least one effect is fitted)"
       for v in ("dtype=None", "")},
    **{f"{_SEL}fitted_columns: {_MASK.format('dtype=bool')} -> {_MASK.format(v)}":
       "a list of bools is a bool array without the dtype, and the design it masks has columns"
       for v in ("dtype=None", "")},
    f"{_SEL}__post_init__: {_RESHAPE.format('-1')} -> {_RESHAPE.format('-2')}":
        "numpy infers a dimension given as any negative number, not only -1",
    f"{_SEL}effect_size: return 0.0 -> return 1.0":
        "unreachable: the contribution has one value per training row and a split always has training rows "
        "(make_split refuses one without)",
}
EQUIVALENT: dict[str, dict[str, str]] = {
    "sim2real/selection.py": SELECTION_EQUIVALENT,
    "envs/sensors.py": _SENSOR_EQUIVALENT,
    "controllers/mpc.py": MPC_EQUIVALENT,
    "controllers/mpc_controller.py": MPC_CONTROLLER_EQUIVALENT,
    "core/trip.py": {
        'xǁTripǁ__post_init__: _check_frame(self.measured, self.units, "measured", truth=False) -> '
        '_check_frame(self.measured, self.units, "measured", truth=None)':
            "unit_of reads the truth catalogue only when truth is truthy; None reads the measured one as False does",
        "x__check_frame: if t.size > 1 and not np.all(np.diff(t) > 0): -> "
        "if t.size >= 1 and not np.all(np.diff(t) > 0):": "one sample has no differences: np.all of none is True",
        f"x_convert_trip_file: {_WITH_TIME} -> {_WITH_TIME.replace('shared_time=True', 'shared_time=None')}": _SHARED,
        f"x_convert_trip_file: {_WITH_TIME} -> {_WITH_TIME.replace('shared_time=True', '')}": _SHARED,
        "x_convert_trip_file: " + _V2.format("> 2"): "only a format-2 file tells them apart, and it is converted "
                                                     "the same whole or streamed (same resolutions either way)",
        "x_convert_trip_file: " + _V2.format(">= 3"): "only a format-2 file tells them apart, and it is converted "
                                                      "the same whole or streamed (same resolutions either way)",
        "x_convert_trip_file: for parts in iter_trip_chunks(source, rows=360_000): -> "
        "for parts in iter_trip_chunks(source, ):": _CHUNKS,
    },
    "core/road_load.py": {
        "x_road_load: return rolling + aero + climbing_force(m, grade, xp) + cornering -> "
        "return rolling + aero + climbing_force(m, grade, ) + cornering": _XP,
        "x_tractive_force: return road_load(speed, grade, curvature, p, xp) + m * acceleration -> "
        "return road_load(speed, grade, curvature, p, ) + m * acceleration": _XP,
        'xǁRoadLoadParametersǁfrom_truth: float(truth["air_density"]), c_y if c_y > 0 else None, headwind, -> '
        'float(truth["air_density"]), c_y if c_y >= 0 else None, headwind,':
            "a zero stiffness passed on is read as none by from_physical (k = 0 when c_yW is falsy)",
        "xǁRoadLoadParametersǁfrom_vector: x = np.asarray(x, dtype=float).ravel() -> "
        "x = np.asarray(x, dtype=None).ravel()": "map(float, x) converts every element to float anyway",
        "xǁRoadLoadParametersǁfrom_vector: x = np.asarray(x, dtype=float).ravel() -> "
        "x = np.asarray(x, ).ravel()": "map(float, x) converts every element to float anyway",
    },
    "core/trip_schema.py": {
        _PAYLOAD + _RAISE.format("None, root='metadata'"): _NO_UNITS,
        _PAYLOAD + _RAISE.format("root='metadata'"): _NO_UNITS,
    },
}

# equivalent wherever they occur: (removed text, added text, why)
EQUIVALENT_EVERYWHERE: tuple[tuple[str, str, str], ...] = (
    ('float("nan")', 'float("NAN")', "float() reads 'nan' in any case"),
    ("rcond=None)", ")", "numpy >= 2 defaults lstsq's rcond to None (machine precision)"),
)

TARGET = 0.85  # killed share of the non-equivalent mutants each module must reach
KILLED = {1, 3}  # a selected test failed (3: pytest internal error)
TIMEOUT = {36, 24, -24, 152, 255, -9}  # CPU limit reached, then killed: the mutant loops or crawls
CRASH = {-11}
UNREACHED = {5, 33}  # no selected test calls the mutated function
STRATA = "strata.json"  # in a staged folder: the pool size and the names of a sampled run


@dataclass
class ModuleScore:
    """Outcome counts of one module's mutants and its score (killed / non-equivalent)."""

    module: str
    total: int = 0
    killed: int = 0
    timeout: int = 0
    survived: int = 0
    unreached: int = 0
    equivalent: int = 0
    other: int = 0
    seconds: float = 0.0
    untested: int = 0  # mutants of the module not in this run's sample (or not reached yet by a stopped run)
    pool: int = 0  # sampled run: the mutants the sample was drawn from (the others were all tested: a census)
    sampled: int = 0  # of ``total``: those of the sample, with their killed (incl. timeouts) and equivalent counts
    sampled_killed: int = 0
    sampled_equivalent: int = 0
    survivors: list[str] = field(default_factory=list)  # "name: diff" of every live non-equivalent mutant
    equivalents: list[str] = field(default_factory=list)

    def _at(self, share: float) -> float:
        """The score when ``share`` of the pool's non-equivalent mutants are killed (census part as counted)."""
        census_live = (self.total - self.sampled) - (self.equivalent - self.sampled_equivalent)
        census_killed = (self.killed + self.timeout) - self.sampled_killed
        pool_live = self.pool * (self.sampled - self.sampled_equivalent) / self.sampled if self.sampled else 0.0
        live = census_live + pool_live
        return (census_killed + share * pool_live) / live if live else float("nan")

    @property
    def score(self) -> float:
        """Killed share of the non-equivalent mutants; for a sampled run the stratified estimate over the census
        part and the pool the sample stands for."""
        if self.pool:
            live = self.sampled - self.sampled_equivalent
            return self._at(self.sampled_killed / live if live else float("nan"))
        live = self.total - self.equivalent
        return (self.killed + self.timeout) / live if live else float("nan")

    @property
    def interval(self) -> tuple[float, float]:
        """95 % interval of the score: Wilson's for the sample's killed share, carried through the stratified
        estimate (no finite-population correction: conservative). Without a sample, Wilson's over the mutants
        tested."""
        if self.pool:
            low, high = wilson_interval(self.sampled_killed, self.sampled - self.sampled_equivalent)
            return self._at(low), self._at(high)
        return wilson_interval(self.killed + self.timeout, self.total - self.equivalent)


def wilson_interval(successes: int, trials: int, z: float = 1.959964) -> tuple[float, float]:
    """Wilson score interval of a binomial proportion (95 % by default); (nan, nan) without trials."""
    if trials <= 0:
        return float("nan"), float("nan")
    p = successes / trials
    centre = (p + z * z / (2 * trials)) / (1 + z * z / trials)
    half = z * math.sqrt(p * (1 - p) / trials + z * z / (4 * trials * trials)) / (1 + z * z / trials)
    return max(0.0, centre - half), min(1.0, centre + half)


def _package_dirs(repo: Path) -> dict[str, Path]:
    """roadload package name -> its source folder, from pyproject's package-dir mapping."""
    cfg = tomllib.loads((repo / "pyproject.toml").read_text())["tool"]["setuptools"]
    return {pkg: repo / folder for pkg, folder in cfg["package-dir"].items()}


def _staged_path(module: str, repo: Path = REPO) -> str:
    """``src/roadload/...`` path of a repository module in the staged (installed) layout."""
    src = (repo / module).resolve()
    best = max(((pkg, folder) for pkg, folder in _package_dirs(repo).items() if src.is_relative_to(folder.resolve())),
               key=lambda item: len(item[0]))
    return str(Path("src", *best[0].split("."), src.relative_to(best[1].resolve())))


def _tests_tree_of(commit: str, target: Path, repo: Path = REPO) -> None:
    """Write the ``tests/`` tree of ``commit`` (any git revision) into ``target`` (its parent folder)."""
    archive = subprocess.run(["git", "-C", str(repo), "archive", "--format=tar", commit, "tests"],
                             capture_output=True)
    if archive.returncode != 0:
        raise SystemExit(f"--tests-from {commit}: git archive failed: {archive.stderr.decode(errors='replace')}")
    subprocess.run(["tar", "-x", "-C", str(target.parent)], input=archive.stdout, check=True)


def modules_at(commit: str, repo: Path = REPO) -> dict[str, tuple[str, ...]]:
    """The ``MODULES`` test selection as it stood at ``commit`` (read from that commit's source, not imported)."""
    shown = subprocess.run(["git", "-C", str(repo), "show", f"{commit}:experiments/mutation.py"],
                           capture_output=True, text=True)
    if shown.returncode != 0:
        raise SystemExit(f"--tests-from {commit}: no experiments/mutation.py there ({shown.stderr.strip()}); "
                         "pass --tests")
    for node in ast.parse(shown.stdout).body:
        if isinstance(node, ast.AnnAssign | ast.Assign):
            targets = [node.target] if isinstance(node, ast.AnnAssign) else node.targets
            if any(isinstance(t, ast.Name) and t.id == "MODULES" for t in targets) and node.value is not None:
                return {k: tuple(v) for k, v in ast.literal_eval(node.value).items()}
    raise SystemExit(f"--tests-from {commit}: its experiments/mutation.py defines no MODULES; pass --tests")


def stage(module: str, tests: tuple[str, ...], folder: Path, repo: Path = REPO, tests_from: str | None = None,
          keep: bool = False) -> Path:
    """A folder laid out as the installed package plus the tests (the working tree's, or those of commit
    ``tests_from``), configured to mutate ``module``. ``keep``: refresh the sources and tests but keep mutmut's
    state (``mutants/``: the mutants, their verdicts, the test map), so that a stopped run continues; mutmut
    itself tests again the mutants of every function whose source changed."""
    if folder.exists():
        for part in ("src", "tests") if keep else ():
            shutil.rmtree(folder / part, ignore_errors=True)
        if not keep:
            shutil.rmtree(folder)
    ignore = shutil.ignore_patterns("__pycache__", "*.pyc", ".hypothesis")
    dirs = _package_dirs(repo)
    for pkg, source in sorted(dirs.items(), key=lambda item: item[0].count(".")):
        target = folder / "src" / Path(*pkg.split("."))
        nested = [Path(*p.split(".")[len(pkg.split(".")):]).parts[0] for p in dirs if p.startswith(pkg + ".")]
        shutil.copytree(source, target, ignore=shutil.ignore_patterns(*nested, "__pycache__", "*.pyc"),
                        dirs_exist_ok=True)
    if tests_from:
        _tests_tree_of(tests_from, folder / "tests", repo)
    else:
        shutil.copytree(repo / "tests", folder / "tests", ignore=ignore)
    table = {
        "source_paths": ["src"],
        "only_mutate": [_staged_path(module, repo)],
        "pytest_add_cli_args": ["-p", "no:cacheprovider", "-m", "not slow"],
        "pytest_add_cli_args_test_selection": list(tests),
        "use_git_change_detection": False,
    }
    lines = ["", "[tool.mutmut]"] + [f"{key} = {json.dumps(value)}" for key, value in table.items()]
    # exists before mutmut starts: an import that met PYTHONPATH's folder missing would cache it as absent
    (folder / "mutants" / "src").mkdir(parents=True, exist_ok=True)
    (folder / "pyproject.toml").write_text((repo / "pyproject.toml").read_text() + "\n".join(lines) + "\n")
    return folder


def _signature(diff: str) -> str:
    """'function: removed -> added' of a mutant's unified diff (whitespace-insensitive, stable across renumbering)."""
    removed = " / ".join(ln[1:].strip() for ln in diff.splitlines() if ln.startswith("-") and not ln.startswith("---"))
    added = " / ".join(ln[1:].strip() for ln in diff.splitlines() if ln.startswith("+") and not ln.startswith("+++"))
    return f"{removed} -> {added}"


def _equivalent_everywhere(signature: str) -> str | None:
    """Why a 'removed -> added' signature is equivalent by one of :data:`EQUIVALENT_EVERYWHERE`, else None."""
    removed, _, added = signature.partition(" -> ")
    for old, new, why in EQUIVALENT_EVERYWHERE:
        at = removed.find(old)
        while at >= 0:  # the mutation may hit any one occurrence
            if removed[:at] + new + removed[at + len(old):] == added:
                return why
            at = removed.find(old, at + 1)
    return None


def collect(module: str, folder: Path, seconds: float, repo: Path = REPO) -> ModuleScore:
    """Count the outcomes stored in the staged run's meta file; name every survivor by its diff."""
    from mutmut.mutation.diff_apply import get_diff_for_mutant

    staged = _staged_path(module, repo)
    meta = json.loads((folder / "mutants" / f"{staged}.meta").read_text())
    known = EQUIVALENT.get(module, {})
    score = ModuleScore(module, seconds=round(seconds, 1))
    strata: dict = json.loads((folder / STRATA).read_text()) if (folder / STRATA).is_file() else {}
    score.pool, sample = int(strata.get("pool", 0)), set(strata.get("sample", []))
    cwd = os.getcwd()
    os.chdir(folder)
    try:
        for name, code in sorted(meta["exit_code_by_key"].items()):
            if code is None:  # outside the sample, or a stopped run's rest
                score.untested += 1
                continue
            score.total += 1
            in_sample = name in sample
            score.sampled += in_sample
            if code in KILLED | TIMEOUT | CRASH:
                score.killed += code in KILLED
                score.timeout += code not in KILLED
                score.sampled_killed += in_sample
                continue
            function = name.rpartition(".")[2].partition("__mutmut_")[0]
            entry = f"{function}: {_signature(get_diff_for_mutant(name, path=staged))}"
            reason = known.get(entry) or _equivalent_everywhere(entry.partition(": ")[2])
            if reason:
                score.equivalent += 1
                score.sampled_equivalent += in_sample
                score.equivalents.append(f"{name}  {entry}  ({reason})")
                continue
            if code in UNREACHED:
                score.unreached += 1
            elif code == 0:
                score.survived += 1
            else:
                score.other += 1
            score.survivors.append(f"{name} [{code}]  {entry}")
    finally:
        os.chdir(cwd)
    return score


def _live_from_previous_run(module: str, folder: Path, repo: Path = REPO) -> dict[str, int]:
    """Exit code of every mutant of the module's previous run in ``folder`` (empty when there is none)."""
    meta = folder / "mutants" / f"{_staged_path(module, repo)}.meta"
    return json.loads(meta.read_text())["exit_code_by_key"] if meta.is_file() else {}


def mutants_of(module: str, folder: Path, repo: Path = REPO) -> tuple[list[str], dict[str, str]]:
    """Every mutant mutmut makes of ``module`` (full names, in mutmut's order) and the hash of each mutated
    function's source, from the staged copy in ``folder``, without running anything (a subprocess: mutmut reads
    its configuration from the working folder)."""
    staged = _staged_path(module, repo)
    code = ("import json, sys; from pathlib import Path; "
            "from mutmut.mutation.file_mutation import mutate_file_contents; "
            "from mutmut.utils.format_utils import get_mutant_name; p = Path(sys.argv[1]); "
            "made = mutate_file_contents(str(p), p.read_text()); "
            "print(json.dumps([[get_mutant_name(p, n) for n in made.mutant_names], made.hash_by_function_name]))")
    out = subprocess.run([sys.executable, "-c", code, staged], cwd=folder, capture_output=True, text=True, check=True)
    names, hashes = json.loads(out.stdout)
    return list(names), dict(hashes)


def _function_of(name: str) -> str:
    """The mangled function name of a mutant (``xǁSelectorǁrank`` of ``roadload....xǁSelectorǁrank__mutmut_3``)."""
    return name.rpartition(".")[2].partition("__mutmut_")[0]


def _plan(module: str, folder: Path, previous: dict, sample: int | None, seed: int, repo: Path = REPO,
          strata: dict | None = None) -> tuple[dict[str, int], list[str]]:
    """The verdicts that stand (killed, timed out or crashed, in a function whose source is unchanged) and the
    mutants to test: all the others, or a seeded sample of ``sample`` of them. A sample is recorded in the
    folder's :data:`STRATA` file with the size of the pool it was drawn from (the score then estimates the pool).
    ``strata``: the previous run's sample. Drawn with the same seed, it is continued (a stopped sampled run): its
    members keep any verdict of an unchanged function and only the others are tested. A larger ``sample`` grows
    it when it was drawn from every mutant: the new members are a seeded sample of the mutants not yet in it (the
    union is again a simple random sample of all of them)."""
    names, hashes = mutants_of(module, folder, repo)
    codes, old_hashes = previous.get("exit_code_by_key", {}), previous.get("hash_by_function_name", {})
    if strata and sample is not None and strata.get("seed") == seed and sample >= len(strata["sample"]):
        return _continue_sample(folder, strata, sample, names, hashes, previous)
    kept = {n: codes[n] for n in names if codes.get(n) in KILLED | TIMEOUT | CRASH
            and old_hashes.get(_function_of(n)) == hashes.get(_function_of(n))}
    pool = [n for n in names if n not in kept]
    (folder / STRATA).unlink(missing_ok=True)
    if sample is None:
        return kept, pool
    chosen = sample_names(pool, sample, seed)
    (folder / STRATA).write_text(json.dumps({"pool": len(pool), "sample": chosen, "seed": seed, "size": sample}))
    return kept, chosen


def _continue_sample(folder: Path, strata: dict, size: int, names: list[str], hashes: dict[str, str],
                     previous: dict) -> tuple[dict[str, int], list[str]]:
    """The standing verdicts of a previous sample's members (any verdict, source unchanged) and the members to
    test; the sample grown to ``size`` first when that is larger (only a sample of every mutant can grow)."""
    codes, old_hashes = previous.get("exit_code_by_key", {}), previous.get("hash_by_function_name", {})
    chosen = list(strata["sample"])
    if size > len(chosen):
        if strata["pool"] != len(names):
            raise SystemExit(f"--sample {size} --resume: the previous sample of {len(chosen)} was drawn from "
                             f"{strata['pool']} of the {len(names)} mutants (after a census); it cannot grow")
        rest = sorted(set(names) - set(chosen))
        chosen = sorted(chosen + sample_names(rest, size - len(chosen), strata["seed"]))
        strata = {**strata, "sample": chosen, "size": size, "grown_from": strata.get("size", len(strata["sample"]))}
    stand = {n: codes[n] for n in chosen if codes.get(n) is not None
             and old_hashes.get(_function_of(n)) == hashes.get(_function_of(n))}
    (folder / STRATA).write_text(json.dumps(strata))
    return stand, [n for n in chosen if n not in stand]


def sample_names(names: list[str], size: int, seed: int) -> list[str]:
    """A seeded simple random sample of ``size`` mutant names (all of them when there are no more)."""
    return sorted(random.Random(seed).sample(sorted(names), min(size, len(names))))


def _mutmut_run(module: str, folder: Path, children: int, names: list[str], only: str | None, append: bool) -> None:
    """``mutmut run`` in the staged ``folder`` (niced; all mutants without a verdict, or only ``names``)."""
    env = {**os.environ, "PYTHONPATH": str(folder / "mutants" / "src"), "PYTHONDONTWRITEBYTECODE": "1"}
    env.pop("MUTANT_UNDER_TEST", None)
    cmd = ["nice", "-n", "15", sys.executable, "-c", "from mutmut.__main__ import cli; cli()", "run",
           "--max-children", str(children)] + ([only] if only else []) + names
    with open(folder / "mutmut.log", "a" if append else "w") as log:
        res = subprocess.run(cmd, cwd=folder, env=env, stdout=log, stderr=subprocess.STDOUT)
    if res.returncode != 0:
        tail = (folder / "mutmut.log").read_text(errors="replace")[-3000:]
        raise RuntimeError(f"mutmut failed on {module} (exit {res.returncode}); log {folder / 'mutmut.log'}:\n{tail}")


def _restrict_verdicts(module: str, folder: Path, keep: Mapping[str, int | None], names: list[str],
                       repo: Path = REPO) -> None:
    """Rewrite the run's meta file: the verdicts of ``names`` (just tested) and ``keep``, every other mutant
    untested (None)."""
    meta_path = folder / "mutants" / f"{_staged_path(module, repo)}.meta"
    meta = json.loads(meta_path.read_text()) if meta_path.is_file() else {"exit_code_by_key": {}}
    now = meta["exit_code_by_key"]
    meta["exit_code_by_key"] = {**dict.fromkeys(now), **keep, **{n: now.get(n) for n in names}}
    meta_path.write_text(json.dumps(meta))


def _live_of(previous: dict) -> tuple[dict[str, int], list[str]]:
    """The killed verdicts of a previous run (they stand) and its tested mutants that were not killed."""
    codes = previous["exit_code_by_key"]
    kept = {n: c for n, c in codes.items() if c in KILLED | TIMEOUT | CRASH}
    return kept, [n for n, c in codes.items() if n not in kept and c is not None]


def run_module(module: str, workdir: Path, children: int, only: str | None = None, repo: Path = REPO,
               tests: tuple[str, ...] | None = None, rerun: bool = False, resume: bool = False,
               sample: int | None = None, seed: int = 0, tests_from: str | None = None) -> ModuleScore:
    """Stage ``module``, run mutmut on it (niced) and count the outcomes.

    ``rerun``: test again only the mutants the previous run of this module left alive (same source, so the same
    mutant names) and keep the previous verdict of the others (and its sample, if it was one). ``resume``: keep
    the killed verdicts of the previous run in the same folder (functions whose source changed excepted) and test
    the rest: a stopped run continues, survivors meet tests added since. ``sample``: test only a seeded random
    sample of that many of the mutants without a standing verdict; the score is then the stratified estimate.
    ``resume`` with the previous run's sample seed: that sample is continued or grown (:func:`_continue_sample`),
    every verdict of its members standing (``rerun`` tests its live ones again).
    ``tests_from``: the tests tree (and, without ``tests``, the selection) of that commit."""
    if tests is None:
        tests = modules_at(tests_from, repo)[module] if tests_from else MODULES[module]
    folder = workdir / module.replace("/", "__").removesuffix(".py")
    meta_path = folder / "mutants" / f"{_staged_path(module, repo)}.meta"
    previous = json.loads(meta_path.read_text()) if (rerun or resume) and meta_path.is_file() else {}
    if rerun and not previous:
        raise SystemExit(f"--rerun: no previous run of {module} in {folder}")
    strata = (folder / STRATA).read_text() if (rerun or resume) and (folder / STRATA).is_file() else None
    folder = stage(module, tests, folder, repo, tests_from, keep=resume)
    if strata and rerun:  # a sampled run tested again: the same sample stands for the same pool
        (folder / STRATA).write_text(strata)
    start = time.monotonic()
    if not (rerun or resume or sample is not None):  # a plain full run
        _mutmut_run(module, folder, children, [], only, append=False)
        return collect(module, folder, time.monotonic() - start, repo)
    kept, names = _live_of(previous) if rerun else _plan(module, folder, previous, sample, seed, repo,
                                                         json.loads(strata) if strata and resume else None)
    if names:
        _mutmut_run(module, folder, children, names, only, append=resume)
    _restrict_verdicts(module, folder, kept, names, repo)  # the standing verdicts, the new ones; the rest untested
    return collect(module, folder, time.monotonic() - start, repo)


def _line(s: ModuleScore) -> str:
    line = (f"{s.module:32s} {s.total:5d} {s.killed:6d} {s.timeout:7d} {s.survived:8d} {s.unreached:9d} "
            f"{s.equivalent:10d} {100 * s.score:6.1f} %  {'ok' if s.score >= TARGET else 'below'}  {s.seconds:7.0f} s")
    low, high = s.interval
    if s.pool:  # a sample: the stratified estimate with its interval
        census = f"all {s.total - s.sampled} others and " if s.total > s.sampled else ""
        line += (f"  ({census}a sample of {s.sampled} of {s.pool} tested; 95 % interval "
                 f"{100 * low:.1f}-{100 * high:.1f} %)")
    elif s.untested:  # a stopped run: the tested ones only
        line += f"  ({s.untested} of {s.total + s.untested} mutants not tested)"
    return line


HEADER = (f"{'module':32s} {'total':>5s} {'killed':>6s} {'timeout':>7s} {'survived':>8s} {'unreached':>9s} "
          f"{'equivalent':>10s} {'score':>8s}")


def _default_repo() -> Path:
    """The source checkout: this module's (an editable install), else the one of the script that was run
    (``scripts/mutation_score.py`` of a checkout with a non-editable install), else the working folder."""
    for candidate in (REPO, Path(sys.argv[0]).resolve().parents[1], Path.cwd()):
        if (candidate / "pyproject.toml").is_file():
            return candidate
    raise SystemExit("no source checkout found (no pyproject.toml beside this module, the script or the working "
                     "folder); pass --repo DIR")


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--module", action="append", choices=sorted(MODULES), help="module(s) to run (default: all)")
    ap.add_argument("--workdir", type=Path, default=Path(tempfile.gettempdir()) / "roadload-mutation",
                    help="scratch folder of the staged copies (each module's is rebuilt on every run)")
    ap.add_argument("--children", type=int, default=1, help="mutants tested at once (default 1: a shared machine)")
    ap.add_argument("--survivors", action="store_true", help="list every surviving mutant with its diff")
    ap.add_argument("--json", type=Path, help="write the per-module counts and survivors here")
    ap.add_argument("--tests", help="comma-separated test files instead of the module's own selection")
    ap.add_argument("--repo", type=Path, default=None,
                    help="source tree to stage (default: the checkout this module or the calling script lives in)")
    ap.add_argument("--quick", action="store_true", help="CI size: core/trip_schema.py against its own test file")
    ap.add_argument("--rerun", action="store_true",
                    help="test again only the mutants the previous run (same --workdir) left alive; keep the others")
    ap.add_argument("--resume", action="store_true",
                    help="continue the previous run in --workdir: keep its killed verdicts (of unchanged functions), "
                         "test the other mutants (survivors meet the tests added since); with --sample and the "
                         "same --seed, continue (or, larger, grow) the previous sample")
    ap.add_argument("--sample", type=int,
                    help="test a seeded random sample of this many of the mutants without a standing verdict; the "
                         "score is the stratified estimate with its 95 %% interval")
    ap.add_argument("--seed", type=int, default=0, help="seed of --sample (default 0)")
    ap.add_argument("--tests-from", metavar="COMMIT",
                    help="score against the tests/ tree of this git revision and its MODULES selection (a before "
                         "score)")
    args = ap.parse_args(argv)
    if args.sample is not None and (args.rerun or args.sample < 1):
        ap.error("--sample takes a positive size and does not combine with --rerun")
    args.repo = args.repo or _default_repo()
    modules = ["core/trip_schema.py"] if args.quick else (args.module or list(MODULES))
    tests = ("tests/core/test_trip_schema.py",) if args.quick else None
    if args.tests:
        tests = tuple(args.tests.split(","))
    print(HEADER, flush=True)
    scores = []
    for module in modules:
        s = run_module(module, args.workdir, args.children, None, args.repo, tests, args.rerun, args.resume,
                       args.sample, args.seed, args.tests_from)
        scores.append(s)
        print(_line(s), flush=True)
    for s in scores:
        if args.survivors and s.survivors:
            print(f"\n{s.module}: {len(s.survivors)} live mutants")
            print("\n".join(f"  {line}" for line in s.survivors))
        if s.equivalents:
            print(f"\n{s.module}: {len(s.equivalents)} equivalent mutants")
            print("\n".join(f"  {line}" for line in s.equivalents))
    if args.json:
        args.json.write_text(json.dumps([{**asdict(s), "score": s.score} for s in scores], indent=1))
    if args.quick and not scores[0].total:
        raise SystemExit("mutation run produced no mutants")


if __name__ == "__main__":
    main()
