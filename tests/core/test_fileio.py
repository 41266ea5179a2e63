import os
import stat

import pytest

from roadload.fileio import atomic_path, write_json, write_text


def test_write_replaces_whole_file_with_ordinary_permissions(tmp_path):
    target = write_text(tmp_path / "sub" / "a.txt", "first")
    write_text(target, "second")
    assert target.read_text() == "second"
    umask = os.umask(0)
    os.umask(umask)
    assert stat.S_IMODE(target.stat().st_mode) == 0o666 & ~umask
    assert [p.name for p in target.parent.iterdir()] == ["a.txt"]


def test_failed_write_keeps_the_old_file_and_leaves_no_temporary(tmp_path):
    target = write_text(tmp_path / "a.json", "old")
    with pytest.raises(TypeError):
        write_json(target, {"x": object()})
    with pytest.raises(RuntimeError):
        with atomic_path(target) as tmp:
            tmp.write_text("half")
            raise RuntimeError("writer died")
    assert target.read_text() == "old"
    assert [p.name for p in tmp_path.iterdir()] == ["a.json"]
