"""The kernel parameter count finds every way a numba kernel is declared and fails above the limit."""

from __future__ import annotations

from pathlib import Path

from roadload.experiments.benchmarks.kernel_signatures import kernel_signatures, main

PLANTED = '''
import numba
from numba import njit, vectorize
from roadload.envs.batch import dependent_jit
from roadload.jitcache import cached_njit

kernel = dependent_jit(__file__)
_inline = njit(inline="always")


@numba.njit(cache=True)
def attribute(a, b):
    return a


@kernel(parallel=True)
def alias_called(a, b, c, d, e, f, g, h, i, j, k, l, m):
    return a


@_inline
def alias_bare(a, b, c):
    return a


@vectorize(["float64(float64)"])
def elementwise(x):
    return x


@cached_njit
def checked_cache(a, b, c, d):
    return a


def plain_python(a, b, c, d, e, f, g, h, i, j, k, l, m, n):
    return a
'''


def test_every_declaration_counts_and_the_largest_fails_the_limit(tmp_path, capsys):
    folder = tmp_path / "envs"
    folder.mkdir()
    (folder / "planted.py").write_text(PLANTED)
    found = [(k.name, k.parameters) for k in kernel_signatures([folder], tmp_path)]
    assert found == [("alias_called", 13), ("checked_cache", 4), ("alias_bare", 3), ("attribute", 2),
                     ("elementwise", 1)]
    assert main(["--folders", "envs", "--limit", "12"], repo=tmp_path) == 1
    assert main(["--folders", "envs", "--limit", "13"], repo=tmp_path) == 0
    assert "largest kernel signature: 13 parameters (envs/planted.py:17 alias_called)" in capsys.readouterr().out


def test_the_simulator_and_gym_kernels_take_at_most_twelve_parameters():
    root = Path(__file__).resolve().parents[3]
    kernels = kernel_signatures([root / "envs", root / "gym-envs"], root)
    assert len(kernels) > 50
    assert kernels[0].parameters <= 12, kernels[0]
