"""What a new user meets in the first hour, each fixed and kept so: packaging without warnings, ``import --format
csv`` without a mapping, readable RL output, a plot without empty panels, scripts that say where they wrote, road
names with "did you mean". (The guides' printed results are checked by .ci/doc_commands.py, tests/docs.)"""

from __future__ import annotations

import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

from roadload.experiments.cli import app

ROOT = Path(__file__).resolve().parents[3]
RUNNER = CliRunner()


def test_the_wheel_builds_without_a_deprecation_or_packaging_warning(tmp_path):
    """pyproject: the licence as an SPDX string, the data folders roadload.io.dbc / .mappings listed as packages."""
    run = subprocess.run([sys.executable, "-m", "pip", "wheel", "-v", "--no-deps", "--no-build-isolation", str(ROOT),
                          "-w", str(tmp_path / "wheel")], capture_output=True, text=True, timeout=600,
                         cwd=tmp_path)
    assert run.returncode == 0, run.stderr[-2000:]
    text = run.stdout + run.stderr
    lines = [ln for ln in text.splitlines() if ("Warning" in ln or "deprecated" in ln) and "byte-compiling" not in ln]
    assert lines == []
    wheel = zipfile.ZipFile(next((tmp_path / "wheel").glob("roadload-*.whl")))
    names = wheel.namelist()
    assert "roadload/io/mappings/plain_csv.json" in names and "roadload/io/dbc/roadload_bmw_i3.dbc" in names


def test_import_format_csv_needs_no_mapping_for_the_plain_csv_columns(tmp_path):
    t = np.arange(0.0, 20.0, 0.05)
    pd.DataFrame({"time_s": t, "speed_kmh": 36.0 + np.sin(t), "accel_x_mps2": np.cos(t) / 3.6,
                  "drive_torque_nm": 50.0 + t}).to_csv(tmp_path / "log.csv", index=False)
    res = RUNNER.invoke(app, ["import", str(tmp_path / "log.csv"), "--format", "csv", "--out",
                              str(tmp_path / "log.parquet")])
    assert res.exit_code == 0, res.output
    from roadload import Trip

    trip = Trip.load(tmp_path / "log.parquet")
    assert trip.meta["mapping"] == "plain_csv"
    np.testing.assert_allclose(trip.channel("vehicle_speed")[:10], (36.0 + np.sin(trip.t[:10])) / 3.6, atol=1e-3)


def test_headline_script_help_exits_zero():
    run = subprocess.run([sys.executable, str(ROOT / "scripts" / "headline.py"), "--help"], capture_output=True,
                         text=True, timeout=300)
    assert run.returncode == 0 and "headline" in run.stdout


def test_unknown_road_names_the_closest_one_and_where_the_list_is():
    from roadload.road_profiles import UnknownProfileError, load_profile

    with pytest.raises(UnknownProfileError, match=r"unknown road profile 'hily' \(did you mean 'hilly'\?\).*known "
                                                  r"names \(\d+, with descriptions: roadload profiles list\)"):
        load_profile("hily")


def test_rl_tables_print_whole_at_80_columns_and_no_curve_is_drawn_without_points(tmp_path):
    from rich.console import Console

    from roadload.experiments.rl.command import print_table
    from roadload.experiments.rl.training import TrainResult, plot_learning_curves

    wide = pd.DataFrame({f"a_rather_long_column_name_{i}": [1.23456, 2.5] for i in range(8)})
    console = Console(width=80, record=True)
    print_table(console, wide, "title")
    lines = console.export_text().splitlines()
    assert lines[0] == "title" and all(f"a_rather_long_column_name_{i}" in lines[1] for i in range(8))
    assert "| 1.23 |" in lines[3]
    empty = TrainResult("ppo", tmp_path / "p.zip", pd.DataFrame(columns=["timesteps", "kind", "value"]), 1.0, 64, {})
    assert plot_learning_curves([empty], tmp_path / "learning_curve.png") is None
    assert not (tmp_path / "learning_curve.png").exists()


def test_the_gym_info_terms_are_plain_floats():
    import gymnasium as gym

    import roadload  # noqa: F401

    env = gym.make("roadload/EcoDrive-v0", route_length=200.0)
    env.reset(seed=0)
    info = env.step(np.array([0.3], dtype=np.float32))[-1]
    env.close()
    assert all(type(v) is float for v in info["terms"].values()) and "np.float64" not in repr(info["terms"])


@pytest.fixture(scope="module")
def plots(tmp_path_factory, hilly_road):
    """The figure roadload simulate --plot draws, for a trip without and with a drifting effect."""
    import roadload.envs.plotting as plotting
    from roadload.envs.simulator import simulate

    figures = {}
    for effects in ([], ["tire_warmup"]):
        trip = simulate("bmw_i3", hilly_road, effects=effects, seed=1, duration=60.0)
        captured = {}
        original = plotting.save_figure

        def keep(fig, out, **kw):
            captured["fig"] = fig
            return original(fig, out, close=False, **kw)

        plotting.save_figure = keep
        try:
            plotting.plot_trip(trip, tmp_path_factory.mktemp("plot") / "trip.png")
        finally:
            plotting.save_figure = original
        figures[bool(effects)] = (trip, captured["fig"])
    return figures


def test_plot_has_no_empty_panel_its_legends_beside_the_axes_and_an_energy_summary(plots):
    from roadload.envs.plotting import drifting_parameters

    trip, fig = plots[False]
    assert drifting_parameters(trip) == {}
    main_axes = [ax for ax in fig.axes if ax.get_ylabel() != "elevation [m]"]
    assert [ax.get_ylabel() for ax in main_axes] == ["speed [km/h]", "force [kN]", "grade [%]"]   # no 4th panel
    for ax in main_axes:
        legend = ax.get_legend()
        assert legend is not None and legend.get_bbox_to_anchor().x0 > ax.get_window_extent().x1  # beside the axes
    grade_labels = [t.get_text() for t in main_axes[2].get_legend().get_texts()]
    assert "elevation (right axis)" in grade_labels
    title = fig._suptitle.get_text()
    assert "no parameter drifts" in title and "kWh/100 km" in title and "battery energy" in title
    trip, fig = plots[True]
    assert "rolling_resistance_f0" in drifting_parameters(trip)
    assert [ax.get_ylabel() for ax in fig.axes if ax.get_ylabel() != "elevation [m]"][-1] == "parameter change [%]"
