"""Checkpointed sweeps: finished tasks survive SIGKILL and are not computed again; corrupt unit files are detected
and rebuilt, never trusted; a resumed sweep returns exactly what an uninterrupted one does."""

import json
import os
import signal
import subprocess
import sys
import textwrap
import time

import numpy as np
import pytest

from roadload.sweep import read_unit, run_sweep, task_key

WORKER = textwrap.dedent("""
    import json, os, sys, time
    from roadload.sweep import run_sweep

    LOG = sys.argv[2]

    def work(task):
        with open(LOG, "a") as fh:  # one line per computation: what a resume must not repeat
            fh.write(f"{task}\\n")
        time.sleep(float(os.environ.get("TASK_SECONDS", "0")))
        return {"task": task, "square": task * task, "root": task ** 0.5, "parts": [task, -task]}

    if __name__ == "__main__":
        out = run_sweep(work, list(range(8)), workers=1, progress=False, checkpoint=sys.argv[1])
        print(json.dumps([o.value for o in out]))
        print(json.dumps([o.source for o in out]), file=sys.stderr)
""")


def _run(tmp_path, seconds="0"):
    script = tmp_path / "worker.py"
    script.write_text(WORKER)
    env = {**os.environ, "TASK_SECONDS": seconds}
    return [sys.executable, str(script), str(tmp_path / "units"), str(tmp_path / "calls.log")], env


def test_a_killed_sweep_resumes_without_recomputing_finished_tasks(tmp_path):
    cmd, env = _run(tmp_path, seconds="0.4")
    proc = subprocess.Popen(cmd, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, start_new_session=True)
    units = tmp_path / "units"
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and len(list(units.glob("*.json"))) < 3:
        time.sleep(0.05)
    os.killpg(proc.pid, signal.SIGKILL)
    proc.wait()
    assert proc.returncode == -signal.SIGKILL
    finished = sorted(units.glob("*.json"))
    assert 3 <= len(finished) < 8
    assert all(read_unit(p)[1] is None for p in finished)  # every unit on disk is whole
    stamps = {p.name: p.stat().st_mtime_ns for p in finished}
    computed_before = (tmp_path / "calls.log").read_text().split()

    cmd, env = _run(tmp_path)
    res = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=120)
    assert res.returncode == 0, res.stderr
    assert f"resumed {len(finished)} of 8 finished tasks" in res.stderr
    calls = (tmp_path / "calls.log").read_text().split()
    # every task computed exactly once over both runs, except the one the kill interrupted (at most one, twice)
    counts = {t: calls.count(str(t)) for t in range(8)}
    assert all(1 <= c <= 2 for c in counts.values()) and sum(c == 2 for c in counts.values()) <= 1, counts
    assert all(counts[int(t)] == 1 for t in computed_before[:len(finished)])
    assert {p.name: p.stat().st_mtime_ns for p in finished} == stamps  # finished units were not rewritten
    assert not [p for p in units.iterdir() if ".roadload-tmp-" in p.name]  # a killed write's temporary is gone
    values = json.loads(res.stdout)
    assert values == [{"task": t, "square": t * t, "root": t ** 0.5, "parts": [t, -t]} for t in range(8)]
    assert json.loads(res.stderr.strip().splitlines()[-1]).count("resumed") == len(finished)


def _square(task):
    return {"x": task, "y": np.float64(task) ** 2, "v": np.arange(3) * task, "t": (task, "a")}


def test_resumed_values_equal_fresh_ones_and_corrupt_units_are_rebuilt(tmp_path, capsys):
    folder = tmp_path / "units"
    fresh = run_sweep(_square, [1, 2, 3, 4], workers=1, progress=False, checkpoint=folder, name=lambda t: f"sq{t}")
    assert [o.source for o in fresh] == ["computed"] * 4
    assert fresh[2].value == {"x": 3, "y": 9.0, "v": [0, 3, 6], "t": [3, "a"]}  # JSON data, as a resume gives it
    files = {t: next(folder.glob(f"sq{t}-*.json")) for t in (1, 2, 3, 4)}
    files[1].write_text(files[1].read_text()[:40])  # truncated (a crash during a non-atomic copy, a full disk)
    doc = json.loads(files[2].read_text())
    doc["value"]["y"] = 5.0  # edited / bit-flipped value: the checksum no longer matches
    files[2].write_text(json.dumps(doc))
    doc = json.loads(files[3].read_text())
    doc["key"] = task_key(_square, 99)  # a unit of another task under this name
    files[3].write_text(json.dumps(doc))
    capsys.readouterr()
    again = run_sweep(_square, [1, 2, 3, 4], workers=1, progress=False, checkpoint=folder, name=lambda t: f"sq{t}")
    err = capsys.readouterr().err
    assert [o.source for o in again] == ["rebuilt", "rebuilt", "rebuilt", "resumed"]
    assert "unreadable" in err and "does not match its checksum" in err and "belongs to another task" in err
    assert [o.value for o in again] == [o.value for o in fresh]
    assert all(read_unit(p)[1] is None for p in folder.glob("*.json"))


def _other(task):
    return {"x": -task}


def test_a_unit_is_reused_only_by_the_same_function_and_task(tmp_path):
    folder = tmp_path / "units"
    run_sweep(_square, [1, 2], workers=1, progress=False, checkpoint=folder)
    out = run_sweep(_other, [1, 2], workers=1, progress=False, checkpoint=folder)
    assert [o.source for o in out] == ["computed", "computed"] and out[0].value == {"x": -1}
    assert task_key(_square, 1) != task_key(_square, 2) != task_key(_other, 2)


def _not_json(task):
    return object()


def test_a_value_that_is_not_json_data_is_a_clear_task_error(tmp_path):
    (out,) = run_sweep(_not_json, [1], workers=1, progress=False, checkpoint=tmp_path / "units")
    assert not out.ok and out.error.startswith("TypeError: a checkpointed sweep stores JSON data; got object")
    assert not list((tmp_path / "units").glob("*.json"))


@pytest.mark.parametrize("workers", [2])
def test_checkpointed_process_pool_matches_serial(tmp_path, workers):
    serial = run_sweep(_square, list(range(5)), workers=1, progress=False, checkpoint=tmp_path / "a")
    pool = run_sweep(_square, list(range(5)), workers=workers, progress=False, checkpoint=tmp_path / "b")
    assert [o.value for o in serial] == [o.value for o in pool]
