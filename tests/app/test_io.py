"""Atomic output files: complete or absent, with ordinary permissions."""

import os

import pytest

from app.io import atomic_path, write_json


def test_written_file_has_umask_permissions(tmp_path):
    write_json(tmp_path / "a.json", {"x": 1})
    umask = os.umask(0)
    os.umask(umask)
    assert (tmp_path / "a.json").stat().st_mode & 0o777 == 0o666 & ~umask
    assert (tmp_path / "a.json").read_text().strip() == '{\n "x": 1\n}'


def test_error_leaves_no_file_and_keeps_the_old_one(tmp_path):
    target = tmp_path / "b.txt"
    target.write_text("old")
    with pytest.raises(RuntimeError), atomic_path(target) as tmp:
        tmp.write_text("half")
        raise RuntimeError("boom")
    assert target.read_text() == "old"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["b.txt"]
