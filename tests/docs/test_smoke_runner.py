"""The smoke stage's script jobs (.ci/smoke.py) run forked from its preloaded process: each must behave as
``python SCRIPT --quick`` would (its own argv, ``__main__``, working folder, log, exit status, exit handlers), and a
benchmark that measures memory must keep its own interpreter."""

from __future__ import annotations

import importlib.util
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
SPEC = importlib.util.spec_from_file_location("ci_smoke", ROOT / ".ci" / "smoke.py")
smoke = importlib.util.module_from_spec(SPEC)
sys.modules["ci_smoke"] = smoke
SPEC.loader.exec_module(smoke)

SCRIPT = '''
import atexit, os, sys
from pathlib import Path

def main():
    print("argv", sys.argv[1:], "name", __name__, "cwd", Path.cwd().name, "path0", Path(sys.path[0]).name)
    atexit.register(lambda: Path("exit_handler_ran").write_text("yes"))
    print("to stderr", file=sys.stderr)
    return int(os.environ.get("SCRIPT_EXIT", "0"))

if __name__ == "__main__":
    sys.exit(main())
'''


def _run(job) -> int:
    """Start ``job`` as .ci/smoke.py does, from a fresh single-threaded interpreter (as smoke.py's process is: a fork
    of this test worker would inherit its threads' locks and exit handlers), and return the job's exit status."""
    code = f"""
import importlib.util, os, sys
from pathlib import Path
spec = importlib.util.spec_from_file_location("ci_smoke", {str(ROOT / ".ci" / "smoke.py")!r})
smoke = importlib.util.module_from_spec(spec)
sys.modules["ci_smoke"] = smoke
spec.loader.exec_module(smoke)
job = smoke.Job("probe", {job.argv!r}, Path({str(job.cwd)!r}), Path({str(job.log)!r}), script=Path({str(job.script)!r}))
_, status = os.waitpid(smoke.start(job)[0], 0)
print("status", os.waitstatus_to_exitcode(status))
"""
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    return int(out.stdout.split("status")[-1])


def _job(tmp_path: Path, body: str):
    scripts, work = tmp_path / "scripts", tmp_path / "work"
    scripts.mkdir()
    work.mkdir()
    script = scripts / "probe.py"
    script.write_text(body)
    return smoke.Job("probe", [sys.executable, str(script), "--quick"], work, tmp_path / "probe.log", script=script)


def test_a_forked_script_job_runs_as_its_own_main_with_its_exit_status_and_exit_handlers(tmp_path, monkeypatch):
    job = _job(tmp_path, SCRIPT)
    monkeypatch.setenv("SCRIPT_EXIT", "3")
    assert _run(job) == 3
    log = job.log.read_text()
    assert "argv ['--quick'] name __main__ cwd work path0 scripts" in log
    assert "to stderr" in log
    assert (tmp_path / "work" / "exit_handler_ran").read_text() == "yes"


def test_a_script_that_raises_fails_with_its_traceback_in_the_log(tmp_path):
    job = _job(tmp_path, "raise RuntimeError('broken on purpose')\n")
    assert _run(job) == 1
    assert "RuntimeError: broken on purpose" in job.log.read_text()


def test_memory_benchmarks_keep_their_own_interpreter_and_the_other_scripts_are_forked(tmp_path):
    jobs = {job.label: job for job in smoke.jobs(tmp_path)}
    for name in smoke.FRESH_INTERPRETER:
        assert (ROOT / "scripts" / name).is_file(), name
        assert jobs[f"scripts/{name} --quick"].script is None
    forked = [job for job in jobs.values() if job.script is not None]
    assert any(job.label == "scripts/kernel_signatures.py --quick" for job in forked)
    assert all(job.argv[-1] == "--quick" for job in forked)
