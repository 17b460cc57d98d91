"""The commands' output files are written whole or not at all (commands/outputs.py)."""

import os
import stat

import pytest

from cdh_planner.commands import outputs
from cdh_planner.commands.outputs import write_pieces, write_text
from cdh_planner.errors import InputError


def _names(folder):
    return sorted(p.name for p in folder.iterdir())


def test_a_write_replaces_the_file_and_leaves_nothing_else(tmp_path):
    out = tmp_path / "out.json"
    out.write_text("old")
    write_text("--json", out, (b"new ", memoryview(b"text")))
    assert out.read_text() == "new text" and _names(tmp_path) == ["out.json"]
    write_text("--json", out, "é")  # a str is UTF-8
    assert out.read_bytes() == "é".encode("utf-8")


@pytest.mark.parametrize("stop", [KeyboardInterrupt, OSError])
def test_an_interrupted_write_leaves_the_old_file(tmp_path, stop):
    out = tmp_path / "out.json"
    out.write_text("old document")

    def pieces():
        yield b"half of a new "
        raise stop()

    with pytest.raises(InputError if stop is OSError else KeyboardInterrupt):
        write_text("--json", out, pieces())
    assert out.read_text() == "old document" and _names(tmp_path) == ["out.json"]


def test_an_interrupted_first_write_leaves_no_file(tmp_path):
    def pieces():
        yield b"{"
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        write_pieces(tmp_path / "out.json", pieces())
    assert _names(tmp_path) == []


def test_permissions_are_kept_and_a_new_file_follows_the_umask(tmp_path):
    out = tmp_path / "out.json"
    out.write_text("old")
    os.chmod(out, 0o640)
    write_text("--json", out, b"new")
    assert stat.S_IMODE(os.stat(out).st_mode) == 0o640
    umask = os.umask(0o027)
    try:
        write_text("--json", tmp_path / "fresh.json", b"x")
    finally:
        os.umask(umask)
    assert stat.S_IMODE(os.stat(tmp_path / "fresh.json").st_mode) == 0o640


def test_a_symbolic_link_is_written_through(tmp_path):
    real = tmp_path / "real.json"
    real.write_text("old")
    link = tmp_path / "link.json"
    link.symlink_to(real)
    write_text("--json", link, b"new")
    assert link.is_symlink() and real.read_text() == "new"


def test_a_device_is_written_in_place(tmp_path):
    write_text("--json", os.devnull, b"nothing")  # no .part beside /dev/null, no replace
    assert os.path.exists(os.devnull) and not stat.S_ISREG(os.stat(os.devnull).st_mode)


def test_without_room_for_a_new_file_the_file_is_written_in_place(tmp_path, monkeypatch):
    """A writable file in a directory that is not (root ignores permission bits, so the
    refusal is simulated)."""
    def refused(path):
        raise PermissionError(13, "Permission denied", str(path))

    monkeypatch.setattr(outputs, "_create", refused)
    out = tmp_path / "out.json"
    out.write_text("old")
    write_text("--json", out, b"new")
    assert out.read_text() == "new"


def test_a_part_file_left_by_a_killed_run_is_replaced(tmp_path):
    out = tmp_path / "out.json"
    (tmp_path / f".out.json.{os.getpid()}.part").write_text("stale")
    write_text("--json", out, b"new")
    assert out.read_text() == "new" and _names(tmp_path) == ["out.json"]


def test_an_existing_file_is_exchanged_in_one_step_and_a_new_one_renamed(tmp_path, monkeypatch):
    """Over an existing file the new one is swapped in (renameat2 RENAME_EXCHANGE, where the
    file system has it) and the old one unlinked; a new file is renamed into place; either
    way the document is whole and nothing else is left. An interruption between the swap and
    the unlink leaves the new document and removes the old one."""
    out, other = tmp_path / "out.json", tmp_path / "link.json"
    out.write_text("old")
    os.link(out, other)  # a second name of the old file keeps the old document
    calls = []
    exchange = outputs._exchange
    monkeypatch.setattr(outputs, "_exchange", lambda a, b: calls.append(exchange(a, b)) or calls[-1])
    write_text("--json", out, b"new")
    write_text("--json", tmp_path / "fresh.json", b"fresh")
    assert out.read_text() == "new" and other.read_text() == "old"
    assert (tmp_path / "fresh.json").read_text() == "fresh"
    assert _names(tmp_path) == ["fresh.json", "link.json", "out.json"]
    assert calls[1] is False  # nothing to exchange with
    if calls[0]:  # ext4, tmpfs, xfs, btrfs
        monkeypatch.setattr(outputs.os, "unlink", _interrupted_once(outputs.os.unlink))
        with pytest.raises(KeyboardInterrupt):
            write_text("--json", out, b"newer")
        assert out.read_text() == "newer" and _names(tmp_path) == ["fresh.json", "link.json", "out.json"]


def _interrupted_once(unlink):
    """``unlink`` that raises KeyboardInterrupt (before unlinking) the first time only."""
    state = {"first": True}

    def interrupted(path):
        if state.pop("first", False):
            raise KeyboardInterrupt
        return unlink(path)
    return interrupted


def test_exchange_refuses_a_missing_file_and_changes_nothing(tmp_path):
    (tmp_path / "a").write_text("a")
    assert outputs._exchange(tmp_path / "a", tmp_path / "b") is False
    assert _names(tmp_path) == ["a"]
