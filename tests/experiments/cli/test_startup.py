"""The command line starts at once: ``roadload --help`` imports no heavy dependency, bad input is refused before
one is imported, the help table matches the commands, and close matches get "did you mean"."""

import json
import subprocess
import sys

import pytest
from typer.testing import CliRunner

from roadload.experiments.cli import BENCHMARKS, COMMANDS, _module_commands, app

#: what a command may import only when it runs (the numba kernels come with numba)
HEAVY = ("torch", "stable_baselines3", "casadi", "numba", "matplotlib", "dask", "distributed", "highway_env", "scipy",
         "asammdf", "sklearn", "gymnasium")
RUNNER = CliRunner()


def _imports_of(argv: list[str], watch: tuple[str, ...] = HEAVY, cwd=None) -> tuple[int, list[str]]:
    """(exit code, the packages of ``watch`` imported: top-level names, or dotted ones) of ``roadload ARGV`` in a
    fresh interpreter."""
    code = ("import sys, json\n"
            f"sys.argv = ['roadload', *{argv!r}]\n"
            "from roadload.experiments.cli import main\n"
            "code = 0\n"
            "try:\n    main()\nexcept SystemExit as exc:\n    code = exc.code or 0\n"
            f"heavy = sorted(w for w in {watch!r} if w in sys.modules)\n"
            "print('RESULT', json.dumps([code, heavy]))\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300, cwd=cwd)
    line = [x for x in out.stdout.splitlines() if x.startswith("RESULT ")]
    assert line, out.stdout + out.stderr
    code, heavy = json.loads(line[-1][len("RESULT "):])
    return code, heavy


def test_help_imports_no_heavy_dependency():
    code, heavy = _imports_of(["--help"])
    assert code == 0 and heavy == []


@pytest.mark.parametrize("argv", [
    ["simulate", "--vehicle", "gt_rdw", "--road", "hilly", "--out", "x.parquet"],
    ["import", "log.csv", "--format", "cvs", "--out", "x.parquet"],
    ["export", "missing.parquet", "--format", "mf4"],
    ["train", "--algo", "ppx"],
    ["simulat"],
])
def test_bad_input_is_refused_before_any_heavy_import(argv):
    code, heavy = _imports_of(argv)
    assert code == 2 and heavy == []


def test_a_streamed_simulate_from_a_road_file_loads_no_pandas_no_scipy_filters_no_gymnasium(tmp_path):
    """What keeps a 1-hour simulate's peak RSS down (scripts/bench_cli_startup.py measures it): pandas (~40 MB),
    scipy.ndimage (~16 MB) and gymnasium (~11 MB) are not imported to stream a trip from a road file."""
    from roadload.road_profiles import load_profile, save_profile
    road = save_profile(load_profile("motorway", seed=0, length=2000.0), tmp_path / "road.json")
    code, loaded = _imports_of(["simulate", "--vehicle", "bmw_i3", "--road", str(road), "--duration", "20", "--out",
                                "trip.parquet"], ("pandas", "scipy.ndimage", "gymnasium", "numba"), cwd=tmp_path)
    assert code == 0 and set(loaded) <= {"numba"}  # numba: on its JIT (the compiled kernels load without it)
    assert (tmp_path / "trip.parquet").exists()


def test_the_help_table_lists_every_command_with_its_own_first_line():
    for table, benchmark in ((COMMANDS, False), (BENCHMARKS, True)):
        by_module: dict[str, set[str]] = {}
        for name, (module, text) in table.items():
            if not module:
                continue
            command = _module_commands(module)[1 if benchmark else 0].commands[name]
            first = " ".join(command.help.split("\n\n")[0].split())
            assert first == text, (name, first, text)
            by_module.setdefault(module, set()).add(name)
        for module, names in by_module.items():   # and no module registers a command the table lacks
            assert set(_module_commands(module)[1 if benchmark else 0].commands) == names, module


def test_cli_copies_of_library_names_agree_with_the_library():
    from roadload.experiments.cli import io as cli_io
    from roadload.experiments.cli import rl as cli_rl
    from roadload.experiments.rl.rollouts import CONTROLLER_BASELINES
    from roadload.io.mapping import FORMATS
    from roadload.trip_storage import PRECISIONS

    assert cli_io.IMPORT_FORMATS == FORMATS and cli_io.PRECISIONS == PRECISIONS
    assert set(cli_rl.BASELINES) == set(CONTROLLER_BASELINES) | {"random"}
    from roadload.experiments.rl.common import VEC_MODES, _algo_class

    assert set(cli_rl.VEC_MODES) == set(VEC_MODES)
    for algo in cli_rl.ALGORITHMS:
        assert _algo_class(algo) is not None


@pytest.mark.parametrize("argv, expected", [
    (["simulat"], "No such command 'simulat'. Did you mean 'simulate', 'estimate'?"),
    (["benchmark", "robustnes"], "Did you mean 'robustness'?"),
    (["simulate", "--vehicle", "gt_rdw", "--road", "hilly", "--out", "x.parquet"],
     "error: --vehicle: unknown vehicle preset 'gt_rdw' (did you mean 'gt_rwd'?); presets: gt_rwd, gt_awd, bmw_i3, "
     "truck_40t, or a vehicle .json file"),
    (["simulate", "--vehicle", "bmw_i3", "--road", "hily", "--out", "x.parquet"],
     "error: --road: unknown road 'hily' (did you mean 'hilly'?); 'roadload profiles list' shows all"),
    (["import", "x.csv", "--format", "cvs", "--out", "x.parquet"],
     "error: --format: unknown import format 'cvs' (did you mean 'csv'?)"),
    (["export", "x.parquet", "--format", "mf5"], "error: --format: unknown export format 'mf5' (did you mean 'mf4'?)"),
    (["simulate", "--vehicle", "bmw_i3", "--road", "hilly", "--out", "x.parquet", "--precision", "compakt"],
     "error: --precision: unknown storage precision 'compakt' (did you mean 'compact'?)"),
])
def test_close_matches_get_did_you_mean(argv, expected):
    res = RUNNER.invoke(app, argv)
    assert res.exit_code == 2 and expected in " ".join(res.output.split()), res.output


def test_simulate_help_lists_every_preset():
    from roadload.presets import PRESETS

    res = RUNNER.invoke(app, ["simulate", "--help"])
    text = " ".join(res.output.split())
    assert res.exit_code == 0 and f"vehicle preset ({', '.join(PRESETS)})" in text and len(PRESETS) == 4


def test_a_missing_input_file_names_a_similar_one(tmp_path):
    (tmp_path / "trip_a.parquet").write_bytes(b"")
    res = RUNNER.invoke(app, ["export", str(tmp_path / "trip_b.parquet"), "--format", "csv"])
    assert res.exit_code == 2 and f"did you mean '{tmp_path / 'trip_a.parquet'}'" in res.output


def test_import_roadload_stays_light_and_still_registers_the_gym_ids():
    """``import roadload`` loads no heavy library, gymnasium included; importing gymnasium afterwards (or before)
    registers every id, whose env then resets."""
    light = ("import sys, roadload\n"
             "heavy = sorted({m.split('.')[0] for m in sys.modules} & {'pandas', 'pyarrow', 'pydantic', 'scipy', "
             "'numba', 'torch', 'matplotlib', 'casadi', 'gymnasium'})\n"
             "import gymnasium\n"
             "print(heavy, [i for i, _, _ in roadload.GYM_ENVS if i not in gymnasium.registry], "
             "roadload.Trip.__name__, gymnasium.__spec__.loader is not None and gymnasium.__loader__ is "
             "gymnasium.__spec__.loader)\n"
             "print(gymnasium.make('roadload/EcoDrive-v0', route_length=300.0).reset(seed=0)[0].shape)\n")
    out = subprocess.run([sys.executable, "-c", light], capture_output=True, text=True, timeout=300)
    assert out.stdout.split("\n")[:2] == ["[] [] Trip True", "(24,)"], out.stdout + out.stderr
    first = "import gymnasium, roadload\nprint([i for i, _, _ in roadload.GYM_ENVS if i not in gymnasium.registry])\n"
    out = subprocess.run([sys.executable, "-c", first], capture_output=True, text=True, timeout=300)
    assert out.stdout.strip() == "[]", out.stdout + out.stderr
