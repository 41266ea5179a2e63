"""A write that runs out of room (disk full, quota, ``ulimit -f``) leaves the old file intact, no temporary file
behind, and gives a clear error naming the path and what ran out."""

import errno
import os
import resource
import subprocess
import sys
from pathlib import Path

import pytest

from roadload.fileio import TMP_MARK, OutputSpaceError, atomic_path, write_text

LIMIT = 64 * 1024  # [bytes] RLIMIT_FSIZE of the writing subprocess


def _limited():
    resource.setrlimit(resource.RLIMIT_FSIZE, (LIMIT, LIMIT))


def _run_limited(code, *args, cwd=None):
    return subprocess.run([sys.executable, "-c", code, *map(str, args)], preexec_fn=_limited, capture_output=True,
                          text=True, timeout=600, cwd=cwd)


@pytest.fixture(scope="module")
def compiled_simulator(tmp_path_factory):
    """The simulator's numba kernels compiled into the cache before a size-limited run: numba's own first-use cache
    write would otherwise hit the file-size limit (errno 27) before the trip write under test."""
    out = tmp_path_factory.mktemp("warm") / "warm.parquet"
    code = ("import sys\nfrom roadload.envs import simulate\nfrom roadload.road_profiles import load_profile\n"
            "simulate('bmw_i3', load_profile('hilly', seed=1), seed=1, duration=2.0, out=sys.argv[1])\n")
    subprocess.run([sys.executable, "-c", code, str(out)], check=True, capture_output=True, timeout=900)


def _leftovers(folder: Path):
    return [p.name for p in folder.iterdir() if TMP_MARK in p.name]


def test_text_write_beyond_the_file_size_limit_keeps_the_old_file(tmp_path):
    target = tmp_path / "runs.json"
    target.write_text('{"old": true}')
    code = ("import sys\nfrom roadload.fileio import OutputSpaceError, write_text\n"
            "try:\n    write_text(sys.argv[1], 'x' * 1_000_000)\n"
            "except OutputSpaceError as e:\n    print(e)\n    raise SystemExit(3)\n")
    res = _run_limited(code, target)
    assert res.returncode == 3, res.stderr
    assert res.stdout.strip() == f"{target}: cannot write: the file-size limit (ulimit -f) was reached; the " \
                                 f"previous file is unchanged"
    assert target.read_text() == '{"old": true}' and not _leftovers(tmp_path)


def test_trip_written_beyond_the_file_size_limit_keeps_the_old_trip(tmp_path, compiled_simulator):
    target = tmp_path / "trip.parquet"
    target.write_bytes(b"an earlier trip")
    code = ("import sys\nfrom roadload.envs import simulate\nfrom roadload.road_profiles import load_profile\n"
            "from roadload.fileio import OutputSpaceError\n"
            "try:\n    simulate('bmw_i3', load_profile('hilly', seed=1), seed=1, duration=60.0, out=sys.argv[1])\n"
            "except OutputSpaceError as e:\n    print(e)\n    raise SystemExit(3)\n")
    res = _run_limited(code, target)
    assert res.returncode == 3, res.stderr[-2000:]
    assert "trip.parquet: cannot write: the file-size limit (ulimit -f) was reached" in res.stdout
    assert target.read_bytes() == b"an earlier trip" and not _leftovers(tmp_path)


def test_cli_reports_a_full_disk_in_one_line_and_keeps_the_old_file(tmp_path, compiled_simulator):
    target = tmp_path / "trip.parquet"
    target.write_bytes(b"an earlier trip")
    roadload = Path(sys.executable).parent / "roadload"
    res = subprocess.run([str(roadload), "simulate", "--vehicle", "bmw_i3", "--road", "hilly", "--duration", "60",
                          "--out", str(target)], preexec_fn=_limited, capture_output=True, text=True, timeout=600)
    assert res.returncode == 1
    lines = [ln for ln in res.stderr.splitlines() if ln.strip()]
    assert lines[-1] == f"error: {target}: cannot write: the file-size limit (ulimit -f) was reached; the previous " \
                        f"file is unchanged", res.stderr[-2000:]
    assert "Traceback" not in res.stderr and "internal" not in lines[-1]
    assert target.read_bytes() == b"an earlier trip" and not _leftovers(tmp_path)


@pytest.mark.parametrize("raised,what", [
    (OSError(errno.ENOSPC, "No space left on device"), "no space left on the device"),
    (OSError(errno.EDQUOT, "Disk quota exceeded"), "the disk quota is exceeded"),
    (OSError("IOError: error writing bytes to file. Detail: [errno 28] No space left on device"),
     "no space left on the device"),  # pyarrow's form: the system message without errno
], ids=["ENOSPC", "EDQUOT", "pyarrow-text"])
def test_every_form_of_a_full_disk_becomes_one_clear_error(tmp_path, raised, what):
    target = tmp_path / "out.csv"
    target.write_text("old")
    with pytest.raises(OutputSpaceError) as err:
        with atomic_path(target) as tmp:
            tmp.write_text("half of it")
            raise raised
    assert str(err.value) == f"{target}: cannot write: {what}; the previous file is unchanged"
    assert err.value.__cause__ is raised
    assert target.read_text() == "old" and not _leftovers(tmp_path)
    fresh = tmp_path / "new.csv"
    with pytest.raises(OutputSpaceError, match="nothing was written"):
        with atomic_path(fresh):
            raise OSError(errno.ENOSPC, "No space left on device")
    assert not fresh.exists()


def test_other_write_errors_pass_through_unchanged(tmp_path):
    with pytest.raises(PermissionError):
        with atomic_path(tmp_path / "x.txt"):
            raise PermissionError(errno.EACCES, "denied")
    write_text(tmp_path / "x.txt", "fine")
    assert (tmp_path / "x.txt").read_text() == "fine" and os.listdir(tmp_path) == ["x.txt"]
