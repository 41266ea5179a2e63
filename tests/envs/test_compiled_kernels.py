"""The ahead-of-time compiled kernels (roadload.compiled, roadload.envs.aot): a streamed ``roadload simulate`` on
them loads neither numba nor llvmlite and writes the same bytes as on numba's JIT; an argument of another type, or a
kernel the extension does not export, switches the process back to numba with the same results; a stale manifest or
a damaged library is not loaded."""

import json
import os
import subprocess
import sys
import textwrap

import pytest

from roadload import compiled

RUN_CLI = textwrap.dedent("""
    import json, sys
    from roadload.experiments.cli import main
    sys.argv = ["roadload", *sys.argv[1:]]
    try:
        main()
    except SystemExit as exc:
        assert not exc.code, exc.code
    from roadload import compiled
    print("RESULT", json.dumps([compiled.active(), "numba" in sys.modules, "llvmlite" in sys.modules]))
""")


def _simulate(tmp_path, out, **env):
    argv = ["simulate", "--vehicle", "gt_rwd", "--road", "hilly", "--duration", "30", "--effects", "all", "--out", out]
    res = subprocess.run([sys.executable, "-c", RUN_CLI, *argv], cwd=tmp_path, capture_output=True, text=True,
                         timeout=900, env={**os.environ, **env})
    line = [x for x in res.stdout.splitlines() if x.startswith("RESULT ")]
    assert res.returncode == 0 and line, res.stdout + res.stderr
    return json.loads(line[-1][len("RESULT "):])


@pytest.fixture(scope="module")
def jit_and_compiled(tmp_path_factory):
    """The same simulate on numba's JIT and on the compiled kernels (a first run builds them when absent)."""
    tmp = tmp_path_factory.mktemp("compiled")
    on_jit = _simulate(tmp, "jit.parquet", ROADLOAD_COMPILED_KERNELS="0")
    _simulate(tmp, "first.parquet")  # builds the extension if this install has none yet
    on_compiled = _simulate(tmp, "compiled.parquet")
    return tmp, on_jit, on_compiled


def test_simulate_on_compiled_kernels_loads_no_numba_and_writes_the_same_bytes(jit_and_compiled):
    tmp, on_jit, on_compiled = jit_and_compiled
    assert on_jit == [False, True, True]  # numba's JIT: numba and llvmlite loaded
    assert on_compiled == [True, False, False]
    assert (tmp / "compiled.parquet").read_bytes() == (tmp / "jit.parquet").read_bytes()


def test_other_argument_types_and_unexported_kernels_switch_to_numba_with_the_same_results(jit_and_compiled):
    code = textwrap.dedent("""
        import sys
        import numpy as np
        from roadload import compiled
        assert compiled.use_compiled_kernels()
        from roadload.envs import Simulator, physics
        from roadload.envs.numerics import road_value_at
        from roadload.road_profiles import load_profile

        road = load_profile("hilly", seed=1, length=3000.0)
        a = Simulator("gt_rwd", road, seed=2)
        a.run(duration=60.0)
        table = np.array([[0.0, 10.0], [1.0, 3.0]])
        here = road_value_at(table, 1, 2.5)  # compiled
        assert compiled.active() and "numba" not in sys.modules
        assert road_value_at(table.astype(np.float32), 1, 2.5) == here  # float32: not what it was compiled for
        assert not compiled.active() and "numba" in sys.modules
        assert type(physics.run_one).__name__ == "CPUDispatcher" and physics._clip(2.0, 0.0, 1.0) == 1.0
        b = Simulator("gt_rwd", road, seed=2)
        b.run(duration=60.0)
        n = int(a.vehicle_state.log_rows)
        assert n == int(b.vehicle_state.log_rows) and a._log[:, :n].tobytes() == b._log[:, :n].tobytes()
        print("OK")
    """)
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=900)
    assert res.returncode == 0 and "OK" in res.stdout, res.stdout + res.stderr


def test_a_changed_source_or_another_build_key_is_not_loaded(tmp_path, jit_and_compiled):
    real = compiled.folder()
    assert real is not None and compiled.read_manifest(real) is not None
    manifest = json.loads((real / "manifest.json").read_text())
    source = tmp_path / "kernel_source.py"
    source.write_text("x = 1\n")
    manifest["sources"] = {**manifest["sources"], str(source): compiled.file_digest(source)}
    (tmp_path / "manifest.json").write_text(json.dumps(manifest))
    assert compiled.read_manifest(tmp_path) is not None
    source.write_text("x = 2\n")  # an edited source: the machine code may differ
    assert compiled.read_manifest(tmp_path) is None
    source.write_text("x = 1\n")
    (tmp_path / "manifest.json").write_text(json.dumps({**manifest, "key": {**manifest["key"], "numba": "0.1"}}))
    assert compiled.read_manifest(tmp_path) is None


def test_a_damaged_library_leaves_numba_in_charge_and_asks_for_a_build(tmp_path, jit_and_compiled):
    manifest = json.loads((compiled.folder() / "manifest.json").read_text())
    code = textwrap.dedent(f"""
        import json, sys
        from roadload import compiled
        d = compiled.folder()
        (d / "broken.so").write_bytes(b"not a shared object")
        (d / "manifest.json").write_text(json.dumps({{**{manifest!r}, "library": "broken.so"}}))
        assert compiled.read_manifest(d) is not None
        assert not compiled.use_compiled_kernels() and compiled.build_wanted
        import roadload.envs
        assert "numba" in sys.modules and not compiled.active()
        print("OK")
    """)
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=900,
                         env={**os.environ, "NUMBA_CACHE_DIR": str(tmp_path)})
    assert res.returncode == 0 and "OK" in res.stdout, res.stdout + res.stderr
