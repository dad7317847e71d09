"""Outputs are written whole and readable by whom the user's umask allows."""

from __future__ import annotations

import os
import stat

import pytest

from eelhost.estimation.optimise import Checkpoint
from eelhost.files import atomic_write, atomic_writer


@pytest.fixture
def umask_022():
    previous = os.umask(0o022)
    yield
    os.umask(previous)


def mode_of(path) -> int:
    return stat.S_IMODE(os.stat(path).st_mode)


def test_atomic_writes_follow_the_umask_as_open_does(tmp_path, umask_022):
    plain = tmp_path / "plain.txt"
    plain.write_text("x")
    atomic_write(tmp_path / "atomic.txt", "x")
    atomic_write(tmp_path / "atomic.bin", b"x")
    assert mode_of(tmp_path / "atomic.txt") == mode_of(tmp_path / "atomic.bin") == mode_of(plain)
    assert mode_of(plain) == 0o644
    os.umask(0o077)
    atomic_write(tmp_path / "private.txt", "x")
    assert mode_of(tmp_path / "private.txt") == 0o600


def test_checkpoints_and_recordings_are_readable_by_the_group(tmp_path, umask_022):
    ck = Checkpoint(tmp_path / "ck.npz", {"seed": 0})
    ck.save({"history": []}, force=True)
    assert mode_of(ck.path) == 0o644
    from eelhost.data.experiments import _atomic_write  # what datasets and recordings use

    _atomic_write(tmp_path / "run.json", "{}")
    assert mode_of(tmp_path / "run.json") == 0o644


def test_a_failed_write_leaves_the_old_file_and_no_temporary(tmp_path):
    target = tmp_path / "table.md"
    target.write_text("old")
    with pytest.raises(RuntimeError), atomic_writer(target) as f:
        f.write("half")
        raise RuntimeError
    assert target.read_text() == "old" and [p.name for p in tmp_path.iterdir()] == ["table.md"]


def test_a_benchmark_block_replaces_its_own_and_keeps_the_hand_written_page(tmp_path):
    from eelhost.files import replace_marked_block

    page = tmp_path / "bench.md"
    replace_marked_block(page, "<!-- b -->", "<!-- e -->", "<!-- b -->\nfirst\n<!-- e -->")
    assert page.read_text() == "<!-- b -->\nfirst\n<!-- e -->\n"
    page.write_text("# Title\n\nby hand\n\n" + page.read_text() + "\nafter, by hand\n")
    replace_marked_block(page, "<!-- b -->", "<!-- e -->", "<!-- b -->\nsecond\n<!-- e -->")
    assert page.read_text() == ("# Title\n\nby hand\n\n<!-- b -->\nsecond\n<!-- e -->\n"
                                "\nafter, by hand\n")
