"""A training killed (SIGKILL) after a checkpoint continues from it: the steps before it are not trained again,
the curve keeps its earlier rows, and a corrupt or foreign checkpoint is not used."""

import json
import os
import signal
import subprocess
import sys
import textwrap
import time

import pytest

from roadload.experiments.rl.training import checkpoint_paths, load_checkpoint

TRAIN = textwrap.dedent("""
    import json, sys
    from roadload.experiments.rl.training import train_policy

    seen = []
    res = train_policy("ppo", 6144, sys.argv[1], n_envs=2, seed=0, vec="native",
                       env_config={"route_length": 300.0}, hyperparams={"n_steps": 256, "batch_size": 128},
                       checkpoint_every=1024, progress=seen.append)
    print(json.dumps({"first_step": seen[0], "timesteps": res.timesteps, "resume": res.extra["resume"],
                      "rows": len(res.curve)}))
""")


@pytest.mark.slow
def test_killed_training_resumes_from_its_checkpoint(tmp_path):
    script = tmp_path / "train.py"
    script.write_text(TRAIN)
    out = tmp_path / "rl"
    state = checkpoint_paths(out, "ppo")["state"]
    proc = subprocess.Popen([sys.executable, str(script), str(out)], stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE, start_new_session=True)
    deadline = time.monotonic() + 600
    while time.monotonic() < deadline and proc.poll() is None:
        if state.exists() and json.loads(state.read_text())["timesteps"] >= 2048:
            break
        time.sleep(0.05)
    os.killpg(proc.pid, signal.SIGKILL)
    proc.wait()
    saved = json.loads(state.read_text())
    done = saved["timesteps"]
    assert 2048 <= done < 6144 and not (out / "ppo_ecodrive.zip").exists()

    res = subprocess.run([sys.executable, str(script), str(out)], capture_output=True, text=True, timeout=600)
    assert res.returncode == 0, res.stderr[-3000:]
    report = json.loads(res.stdout.strip().splitlines()[-1])
    assert report["resume"] == f"resumed at {done} of 6144 steps from {state}"
    assert report["first_step"] > done  # training continued after the checkpoint, not from step 0
    assert report["timesteps"] >= 6144 and report["rows"] >= len(saved["rows"])
    assert (out / "ppo_ecodrive.zip").exists() and not state.exists()  # the checkpoint served and is gone


def test_a_corrupt_or_foreign_checkpoint_is_not_used(tmp_path):
    paths = checkpoint_paths(tmp_path, "ppo")
    identity = {"algo": "ppo", "timesteps": 100}
    paths["model"].write_bytes(b"model bytes")
    import hashlib

    good = {"identity": identity, "timesteps": 50, "rows": [], "next_eval": 0,
            "model_sha256": hashlib.sha256(b"model bytes").hexdigest()}
    paths["state"].write_text(json.dumps(good))
    assert load_checkpoint(tmp_path, "ppo", identity)[0] == good
    state, why = load_checkpoint(tmp_path, "ppo", {**identity, "timesteps": 200})
    assert state is None and "another training run" in why
    paths["model"].write_bytes(b"model bytes, half overwritten")
    state, why = load_checkpoint(tmp_path, "ppo", identity)
    assert state is None and "does not match its checksum" in why
    paths["state"].write_text('{"identity": ')
    state, why = load_checkpoint(tmp_path, "ppo", identity)
    assert state is None and "unreadable" in why
