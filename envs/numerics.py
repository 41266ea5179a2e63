"""Jitted numerical helpers of the simulator core: a small seeded random generator and table interpolation.

The generator is splitmix64 on the ``random_state`` field (uint64) of a vehicle's state record, so several
simulators in one process never share random state (numba's ``np.random`` is process-global). Tables live in one
flat float64 array ``tables.values``; row k of the int64 descriptor array ``tables.descriptors`` is (offset_x, n_x,
offset_y, n_y, offset_values) where for a 1-D curve offset_y points to the n_x values and for a 2-D map
values[i][j] = f(x[i], y[j]) are stored row-major.
"""

from __future__ import annotations

import math

import numpy as np
from ._jit import jit

_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_M1 = np.uint64(0xBF58476D1CE4E5B9)
_M2 = np.uint64(0x94D049BB133111EB)
_S30 = np.uint64(30)
_S27 = np.uint64(27)
_S31 = np.uint64(31)
_S11 = np.uint64(11)


@jit(inline=True)
def rng_next(x):
    """Next 64-bit output of splitmix64 on the state record's ``random_state``."""
    x.random_state += _GOLDEN
    z = x.random_state
    z = (z ^ (z >> _S30)) * _M1
    z = (z ^ (z >> _S27)) * _M2
    return z ^ (z >> _S31)


@jit(inline=True)
def rng_uniform(x):
    """Uniform in [0, 1)."""
    return float(rng_next(x) >> _S11) * (1.0 / 9007199254740992.0)


@jit(inline=True)
def rng_normal(x):
    """Standard normal (Box-Muller)."""
    u1 = rng_uniform(x)
    if u1 < 1e-300:
        u1 = 1e-300
    u2 = rng_uniform(x)
    return math.sqrt(-2.0 * math.log(u1)) * math.cos(2.0 * math.pi * u2)


SMALL_ANGLE = 2.0 ** -30
"""|x| [rad] below which sin x, tan x, asin x, atan x round to x and cos x to 1 (the neglected terms, x^3 / 6 or
x^3 / 3 and x^2 / 2, are below 2^-58 of the result, far under half its last bit); libm returns exactly these values
there (glibc: its own small-argument branches, taken up to 2^-27 and beyond; tests/envs/test_kernel_exactness.py
compares every function bit for bit over that range). The ``*_small`` functions return them without the call: on a
straight road the single-track model's angles are exactly 0 (five calls per substep), and a traffic vehicle that has
changed lanes keeps a heading and an offset from its centre line of ~1e-16 for the rest of the episode (its steering
and bicycle step: ten calls per frame, roadload.gym.traffic_model)."""


@jit(inline=True)
def sin_small(x):
    """sin x, without the call where it rounds to x (|x| < SMALL_ANGLE)."""
    return x if abs(x) < SMALL_ANGLE else math.sin(x)


@jit(inline=True)
def cos_small(x):
    """cos x, without the call where it rounds to 1 (|x| < SMALL_ANGLE)."""
    return 1.0 if abs(x) < SMALL_ANGLE else math.cos(x)


@jit(inline=True)
def tan_small(x):
    """tan x, without the call where it rounds to x (|x| < SMALL_ANGLE)."""
    return x if abs(x) < SMALL_ANGLE else math.tan(x)


@jit(inline=True)
def asin_small(x):
    """asin x, without the call where it rounds to x (|x| < SMALL_ANGLE)."""
    return x if abs(x) < SMALL_ANGLE else math.asin(x)


@jit(inline=True)
def atan_small(x):
    """atan x, without the call where it rounds to x (|x| < SMALL_ANGLE)."""
    return x if abs(x) < SMALL_ANGLE else math.atan(x)


@jit(inline=True)
def segment(tabs, off, n, x):
    """Index i and weight w with x = (1-w) a[i] + w a[i+1] on the increasing axis tabs[off:off+n], clamped."""
    if x <= tabs[off]:
        return 0, 0.0
    if x >= tabs[off + n - 1]:
        return n - 2, 1.0
    lo = 0
    hi = n - 1
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if tabs[off + mid] <= x:
            lo = mid
        else:
            hi = mid
    return lo, (x - tabs[off + lo]) / (tabs[off + lo + 1] - tabs[off + lo])


@jit(inline=True)
def table1(tables, k, x):
    """Curve k at x (linear, clamped)."""
    tabs, ti = tables
    ox = ti[k, 0]
    n = ti[k, 1]
    oy = ti[k, 2]
    i, w = segment(tabs, ox, n, x)
    return tabs[oy + i] * (1.0 - w) + tabs[oy + i + 1] * w


@jit(inline=True)
def table2(tables, k, x, y):
    """Map k at (x, y) (bilinear, clamped)."""
    tabs, ti = tables
    j, w = segment(tabs, ti[k, 2], ti[k, 3], y)
    return table2_at(tables, k, x, j, w)


@jit(inline=True)
def table2_at(tables, k, x, j, w):
    """Map k at (x, y) with y's segment (j, w) on its y axis already found (``segment``): bilinear, clamped."""
    tabs, ti = tables
    ox = ti[k, 0]
    nx = ti[k, 1]
    ny = ti[k, 3]
    ov = ti[k, 4]
    i, u = segment(tabs, ox, nx, x)
    a = ov + i * ny + j
    b = a + ny
    return ((1.0 - u) * ((1.0 - w) * tabs[a] + w * tabs[a + 1])
            + u * ((1.0 - w) * tabs[b] + w * tabs[b + 1]))


@jit(inline=True)
def invert_through_map(tables, k, ratio, scale, speed, target):
    """Solve T*ratio - scale*f_k(T, speed) = target for T, f_k piecewise linear in T (x axis) at fixed speed.

    Exact for the bilinear map (clamped beyond the torque axis, where the left side has slope ``ratio``);
    requires ratio > scale * df/dT (true for any physical loss map).
    """
    tabs, ti = tables
    j, w = segment(tabs, ti[k, 2], ti[k, 3], speed)
    return invert_through_map_at(tables, k, ratio, scale, j, w, target)


@jit(inline=True)
def invert_through_map_at(tables, k, ratio, scale, j, w, target):
    """:func:`invert_through_map` with the speed's segment (j, w) on the map's y axis already found."""
    tabs, ti = tables
    ox = ti[k, 0]
    nx = ti[k, 1]
    ny = ti[k, 3]
    ov = ti[k, 4]
    t_prev = tabs[ox]
    f_prev = (1.0 - w) * tabs[ov + j] + w * tabs[ov + j + 1]
    g_prev = t_prev * ratio - scale * f_prev
    if target <= g_prev:
        return t_prev + (target - g_prev) / ratio
    for i in range(1, nx):
        t_i = tabs[ox + i]
        a = ov + i * ny + j
        g_i = t_i * ratio - scale * ((1.0 - w) * tabs[a] + w * tabs[a + 1])
        if target <= g_i:
            return t_prev + (target - g_prev) * (t_i - t_prev) / (g_i - g_prev)
        t_prev = t_i
        g_prev = g_i
    return t_prev + (target - g_prev) / ratio


@jit(inline=True)
def _bisect(s_axis, s):
    """Segment index of s on the increasing axis s_axis (clamped): segment()'s search on a whole array."""
    return segment(s_axis, 0, s_axis.shape[0], s)[0]


@jit(inline=True)
def road_locate(s_axis, s, idx):
    """Index i with s_axis[i] <= s < s_axis[i+1] (clamped), starting at the cached index idx (monotone travel)."""
    n = s_axis.shape[0]
    if idx < 0 or idx > n - 2 or s < s_axis[idx]:
        return _bisect(s_axis, s)
    steps = 0
    while idx < n - 2 and s >= s_axis[idx + 1]:
        idx += 1
        steps += 1
        if steps > 8:  # far jump: fall back to bisection
            return _bisect(s_axis, s)
    return idx


@jit(inline=True)
def road_value(road, row, i, s):
    """Linear interpolation of road[row] at s inside segment i (clamped to the profile ends)."""
    return road_blend(road, row, i, road_weight(road, i, s))


@jit(inline=True)
def road_weight(road, i, s):
    """Weight w in [0, 1] of s in segment i: s = (1 - w) s_i + w s_i+1 (clamped); one division shared by every row
    read at the same s (road_blend)."""
    s0 = road[0, i]
    s1 = road[0, i + 1]
    w = (s - s0) / (s1 - s0)
    if w < 0.0:
        w = 0.0
    elif w > 1.0:
        w = 1.0
    return w


@jit(inline=True)
def road_blend(road, row, i, w):
    """(1 - w) road[row, i] + w road[row, i + 1]."""
    return road[row, i] * (1.0 - w) + road[row, i + 1] * w


@jit(inline=True)
def road_value_at(road, row, s):
    """road[row] at any s (binary search)."""
    return road_value_near(road, row, s, -1)


@jit(inline=True)
def road_value_near(road, row, s, idx):
    """road[row] at s [m], the segment searched from index idx onwards (road_locate; -1: binary search) — for a
    preview a few grid steps ahead of the vehicle's cached index. Clamped to the profile ends."""
    n = road.shape[1]
    if s <= road[0, 0]:
        return road[row, 0]
    if s >= road[0, n - 1]:
        return road[row, n - 1]
    i = road_locate(road[0], s, idx)
    return road_value(road, row, i, s)
