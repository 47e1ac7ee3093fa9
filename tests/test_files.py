"""Writing under a temporary name of the writer's own: two writers of one file or one folder
at once both succeed, a failed writer leaves nothing, and a reader never sees half."""

from __future__ import annotations

from pathlib import Path

import pytest

from oricf.files import atomic_file, staged_folder, write_atomically


def test_two_writers_of_one_file_at_once_both_succeed(tmp_path: Path) -> None:
    path = tmp_path / "model.onnx"
    with atomic_file(path) as first:
        first.write(b"first")
        with atomic_file(path) as second:
            second.write(b"second")
        assert path.read_bytes() == b"second"  # whole, while the first still writes
    assert path.read_bytes() == b"first"
    assert [p.name for p in tmp_path.iterdir()] == ["model.onnx"]
    assert path.stat().st_mode & 0o777 == 0o644


def test_a_failed_writer_leaves_the_file_as_it_was(tmp_path: Path) -> None:
    path = tmp_path / "ca.key"
    write_atomically(path, b"kept", 0o600)
    with pytest.raises(RuntimeError), atomic_file(path) as out:
        out.write(b"half")
        raise RuntimeError("the writer failed")
    assert path.read_bytes() == b"kept"
    assert path.stat().st_mode & 0o777 == 0o600
    assert [p.name for p in tmp_path.iterdir()] == ["ca.key"]


def test_a_link_is_replaced_never_written_through(tmp_path: Path) -> None:
    outside = tmp_path / "outside"
    outside.write_bytes(b"untouched")
    link = tmp_path / "token"
    link.symlink_to(outside)
    write_atomically(link, b"secret", 0o600)
    assert not link.is_symlink() and link.read_bytes() == b"secret"
    assert outside.read_bytes() == b"untouched"


def test_two_writers_of_one_folder_at_once_keep_the_first_in_place(tmp_path: Path) -> None:
    folder = tmp_path / "trained" / "abc"
    with staged_folder(folder) as first:
        (first / "policy.yaml").write_text("first")
        with staged_folder(folder) as second:
            (second / "policy.yaml").write_text("second")
    assert (folder / "policy.yaml").read_text() == "second"
    assert [p.name for p in folder.parent.iterdir()] == ["abc"]


def test_a_failed_folder_writer_leaves_nothing(tmp_path: Path) -> None:
    folder = tmp_path / "abc"
    with pytest.raises(RuntimeError), staged_folder(folder) as staged:
        (staged / "policy.onnx").write_bytes(b"half")
        raise RuntimeError("training failed")
    assert list(tmp_path.iterdir()) == []
