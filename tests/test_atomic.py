"""symoro_gen.atomic: outputs appear whole or not at all, with ordinary permissions."""
import os
import stat

import pytest

from symoro_gen.atomic import (
    ordinary_mode,
    replace_folder_atomic,
    write_bytes_atomic,
    write_text_atomic,
)


def _mode(p):
    return stat.S_IMODE(os.stat(p).st_mode)


def test_write_replace_and_no_clobber(tmp_path):
    p = tmp_path / "sub" / "a.txt"
    write_text_atomic(p, "one\n")
    assert p.read_text() == "one\n" and _mode(p) == ordinary_mode()
    write_text_atomic(p, "two\n")
    assert p.read_text() == "two\n"
    with pytest.raises(FileExistsError):
        write_bytes_atomic(p, b"three", overwrite=False)
    assert p.read_text() == "two\n"
    write_bytes_atomic(tmp_path / "b.bin", b"\x00\x01", overwrite=False)
    assert (tmp_path / "b.bin").read_bytes() == b"\x00\x01"
    assert sorted(x.name for x in tmp_path.rglob("*")) == ["a.txt", "b.bin", "sub"]  # no temporary left


def test_failed_write_leaves_the_old_file(tmp_path, monkeypatch):
    p = tmp_path / "a.txt"
    write_text_atomic(p, "old")

    def boom(*a):
        raise OSError("disk full")

    monkeypatch.setattr(os, "replace", boom)
    with pytest.raises(OSError, match="disk full"):
        write_text_atomic(p, "new")
    assert p.read_text() == "old" and [x.name for x in tmp_path.iterdir()] == ["a.txt"]


def test_replace_folder(tmp_path):
    d = tmp_path / "imgs"
    replace_folder_atomic(d, {"a.png": b"A", "b.md": "text"})
    assert sorted(x.name for x in d.iterdir()) == ["a.png", "b.md"] and _mode(d) == ordinary_mode(is_dir=True)
    replace_folder_atomic(d, {"c.png": b"C"})
    assert [x.name for x in d.iterdir()] == ["c.png"]
    assert [x.name for x in tmp_path.iterdir()] == ["imgs"]  # neither the temporary nor the old folder left
    (tmp_path / "f").write_text("x")
    with pytest.raises(NotADirectoryError):
        replace_folder_atomic(tmp_path / "f", {"a": b""})
