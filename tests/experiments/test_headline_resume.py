"""A headline run killed (SIGKILL) after its first finished seed resumes to the same tables as an uninterrupted
run, without computing that seed again."""

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from roadload.sweep import read_unit

TABLES = ("summary.csv", "summary_other_metric.csv", "headline.md")


def headline(out):
    roadload = Path(sys.executable).parent / "roadload"  # the console script of this environment
    return [str(roadload), "benchmark", "headline", "--quick", "--out", str(out), "--workers", "1"]


@pytest.mark.slow
def test_killed_headline_run_resumes_to_the_same_tables(tmp_path):
    whole = subprocess.run(headline(tmp_path / "whole"), capture_output=True, text=True, timeout=900)
    assert whole.returncode == 0, whole.stderr[-2000:]

    out = tmp_path / "killed"
    proc = subprocess.Popen(headline(out), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                            start_new_session=True)
    deadline = time.monotonic() + 900
    while time.monotonic() < deadline and not list((out / "tasks").glob("*.json")) and proc.poll() is None:
        time.sleep(0.1)
    os.killpg(proc.pid, signal.SIGKILL)
    proc.wait()
    (first,) = list((out / "tasks").glob("*.json"))  # one seed finished, the second was running
    assert read_unit(first)[1] is None and not (out / "summary.csv").exists()
    stamp = first.stat().st_mtime_ns

    resumed = subprocess.run(headline(out), capture_output=True, text=True, timeout=900)
    assert resumed.returncode == 0, resumed.stderr[-2000:]
    assert "resumed 1 of 2 finished tasks" in resumed.stderr
    assert first.stat().st_mtime_ns == stamp  # the finished seed was taken as it was
    for name in TABLES:
        assert (out / name).read_bytes() == (tmp_path / "whole" / name).read_bytes(), name
