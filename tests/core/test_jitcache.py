"""The numba cache under faults: 4 processes starting at once on an empty cache (as Dask workers and SubprocVecEnv
do) all succeed with identical results; a damaged cache is detected, rebuilt and gives the same results.

Scope 'light' (default suite): the road generator, the robust-weight ufunc of the estimators and the gym env's
preview kernels (three layers, quick to compile). Scope 'full' (slow): also the estimator record loop, the
simulator core and the native vector env."""

import os
import subprocess
import sys
import textwrap

import pytest

KERNELS = textwrap.dedent("""
    import hashlib, sys
    import numpy as np
    from roadload.road_profiles import load_profile
    from roadload.estimators.influence import _weight_vec
    from roadload.gym.ecodrive import RouteTable

    h = hashlib.sha256()
    road = load_profile("hilly", seed=3)
    h.update(road.grade.tobytes())
    h.update(_weight_vec(np.ones(5, np.int64), np.linspace(-3, 3, 5), 1.345, 0.0, 0.0).tobytes())
    table = RouteTable(road, np.array([0.0, 50.0, 200.0]), 0.9, 2.0)
    h.update(table.look_ahead(123.4).tobytes())
    h.update(table.braking_envelope(0.5, 1.0).tobytes())
    if sys.argv[1] == "full":
        from roadload.estimators import run
        from roadload.envs import simulate

        rng = np.random.default_rng(0)
        A = rng.normal(size=(400, 2))
        B = A @ np.array([1.5, -0.5]) + 0.01 * rng.normal(size=400)
        h.update(np.asarray(run("RRLM", A, B).X).tobytes())
        from roadload.gym.ecodrive import EcoDriveEnv
        from roadload.gym.vector import EcoDriveVectorEnv

        h.update(simulate("bmw_i3", road, seed=3, duration=20.0).measured.to_numpy().tobytes())
        env = EcoDriveEnv(config={"route_length": 200.0})
        obs, _ = env.reset(seed=1)
        venv = EcoDriveVectorEnv(2, config={"route_length": 200.0})
        vobs, _ = venv.reset(seed=1)
        for _ in range(20):
            obs = env.step(np.array([0.5], np.float32))[0]
            vobs = venv.step(np.full((2, 1), 0.5, np.float32))[0]
        h.update(obs.tobytes())
        h.update(vobs.tobytes())
    print(h.hexdigest())
""")


def _env(cache):
    return {**os.environ, "NUMBA_CACHE_DIR": str(cache)}


def _run(cache, script, scope):
    return subprocess.run([sys.executable, str(script), scope], env=_env(cache), capture_output=True, text=True,
                          timeout=3600)


def cold_starts(folder, scope):
    script = folder / "kernels.py"
    script.write_text(KERNELS)
    cache = folder / "cache"
    procs = [subprocess.Popen([sys.executable, str(script), scope], env=_env(cache), stdout=subprocess.PIPE,
                              stderr=subprocess.PIPE, text=True) for _ in range(4)]  # one empty cache, 4 at once
    results = [(p.wait(timeout=3600), *p.communicate()) for p in procs]
    return cache, script, results


def check_cold_starts_agree(cache, script, results, scope, min_index_files):
    for code, out, err in results:
        assert code == 0, err[-3000:]
        assert "is corrupt" not in err
    digests = {out.strip() for _, out, _ in results}
    assert len(digests) == 1, digests
    assert len(list(cache.rglob("*.nbi"))) >= min_index_files  # the kernels were cached in the shared folder
    warm = _run(cache, script, scope)
    assert warm.returncode == 0 and warm.stdout.strip() in digests and "is corrupt" not in warm.stderr


def check_damaged_cache_is_rebuilt(cache, script, expected, scope):
    index, data = sorted(cache.rglob("*.nbi")), sorted(cache.rglob("*.nbc"))
    for path in index[::2]:  # half the index files truncated, half the data files cut in two
        path.write_bytes(path.read_bytes()[:60])
    for path in data[1::2]:
        blob = path.read_bytes()
        path.write_bytes(blob[:len(blob) // 2])
    run = _run(cache, script, scope)
    assert run.returncode == 0, run.stderr[-3000:]
    assert run.stdout.strip() == expected
    assert run.stderr.count("is corrupt") >= 2 and "compiling it again" in run.stderr
    again = _run(cache, script, scope)
    assert again.returncode == 0 and again.stdout.strip() == expected and "is corrupt" not in again.stderr


@pytest.fixture(scope="module")
def light(tmp_path_factory):
    return cold_starts(tmp_path_factory.mktemp("numba_light"), "light")


def test_four_concurrent_cold_starts_agree(light):
    check_cold_starts_agree(*light, "light", min_index_files=5)


def test_a_damaged_cache_is_rebuilt_not_trusted(light):
    cache, script, results = light
    check_damaged_cache_is_rebuilt(cache, script, results[0][1].strip(), "light")


@pytest.mark.slow
@pytest.mark.nightly  # minutes of compilation on 2 cores: outside the 15-minute CI, run by .ci/nightly
def test_four_concurrent_cold_starts_of_every_kernel_agree(tmp_path):
    """Every kernel, simulator core and vector env included (the damage test above uses the same CheckedCache)."""
    cache, script, results = cold_starts(tmp_path, "full")
    check_cold_starts_agree(cache, script, results, "full", min_index_files=40)


RUNTIME = textwrap.dedent("""
    import numpy as np
    from numba.core.runtime import rtsys
    from roadload import jitcache
    from roadload.jitcache import cached_njit

    @cached_njit
    def doubled_cumsum(n):
        out = np.empty(n)  # an NRT allocation: freed through the runtime's NRT_decref
        acc = 0.0
        for i in range(n):
            acc += 2.0 * i
            out[i] = acc
        return out

    total = sum(float(doubled_cumsum(1000)[-1]) for _ in range(50))
    stats = rtsys.get_allocation_stats()
    print(total, stats.alloc - stats.free, stats.mi_alloc - stats.mi_free, jitcache.runtime_origin)
""")


def test_the_runtime_module_is_loaded_from_the_cache_and_frees_what_kernels_allocate(tmp_path):
    """numba's runtime (NRT) module is compiled on the first run and its object code loaded on the next; a kernel
    allocates and frees through either alike (NRT statistics: nothing left allocated); a damaged file is rebuilt."""
    script = tmp_path / "runtime_kernel.py"
    script.write_text(RUNTIME)
    env = {**_env(tmp_path / "cache"), "NUMBA_NRT_STATS": "1"}

    def run():
        out = subprocess.run([sys.executable, str(script)], env=env, capture_output=True, text=True, timeout=600)
        assert out.returncode == 0, out.stderr[-3000:]
        return out.stdout.split(), out.stderr

    expected = str(50 * 999.0 * 1000.0)
    (total, live, live_mi, from_cache), _ = run()  # cold: the kernel and the runtime compiled, both stored
    assert (total, live, live_mi, from_cache) == (expected, "0", "0", "compiled")
    [stored] = tmp_path.rglob("numba_runtime.*.nbc")
    (total, live, live_mi, from_cache), _ = run()  # warm kernel and runtime: object code loaded
    assert (total, live, live_mi, from_cache) == (expected, "0", "0", "cache")
    stored.write_bytes(stored.read_bytes()[:100])
    (total, live, live_mi, from_cache), err = run()
    assert (total, live, live_mi, from_cache) == (expected, "0", "0", "compiled") and "is corrupt" in err
    assert run()[0] == [expected, "0", "0", "cache"]
