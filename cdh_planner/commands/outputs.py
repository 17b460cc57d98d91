"""Output files of the commands (``--json``, ``--plot``, ``-o``): checked before the work
starts, and a failure to write them (a full disk, EIO) is an InputError naming the
option, i.e. one line and exit 2, never a traceback after minutes of planning. An output
is never one of the command's inputs (nor another of its outputs): ``plan P.yaml --json
P.yaml`` is refused before the work, through symbolic and hard links too.
"""

import os
from contextlib import contextmanager, suppress
from pathlib import Path

from ..errors import InputError


def check_output(option, path, suffixes=(), inputs=()):
    """``path`` as a Path if a file can be written there: its directory exists and is
    writable, and the path is not a directory itself (nor a name with a NUL character);
    an existing file must be writable (``/dev/null`` is fine). ``suffixes``: the
    extensions allowed (e.g. ``(".png",)``), any when empty. ``inputs``: (label, path)
    pairs of the other files of the command, read or written (label e.g. "the problem
    file", "the --json output"; a None path is skipped); ``path`` must be none of them."""
    text = os.fspath(path)
    if not text or "\x00" in text:
        raise InputError(option, text, "expected the path of a file to write")
    out = Path(text)
    if suffixes and out.suffix.lower() not in suffixes:
        raise InputError(option, text, f"expected a {' or '.join(suffixes)} file")
    for label, other in inputs:
        if other is not None and same_file(out, other):
            raise InputError(option, text, f"is {label} ({os.fspath(other)}): it would be "
                                           f"overwritten; give another name")
    try:
        if out.is_dir():
            raise InputError(option, text, "is a directory: give a file name")
        parent = out.parent if str(out.parent) else Path(".")
        if not parent.is_dir():
            raise InputError(option, text, "directory does not exist")
        if out.exists():
            if not os.access(out, os.W_OK):
                raise InputError(option, text, "file is not writable")
        elif not os.access(parent, os.W_OK | os.X_OK):
            raise InputError(option, text, "directory is not writable")
    except OSError as exc:  # a name too long, a loop of links
        raise InputError(option, text, f"cannot write: {exc.strerror or exc}") from None
    return out


def same_file(a, b):
    """Whether paths ``a`` and ``b`` name one file: the same path once symbolic links,
    ``..`` and ``.`` are resolved (whether it exists or not), or two names (hard links)
    of one existing file."""
    try:
        if os.path.realpath(a) == os.path.realpath(b):
            return True
        return os.path.exists(a) and os.path.exists(b) and os.path.samefile(a, b)
    except (OSError, ValueError):  # a name too long, a NUL: names no file another names
        return False


@contextmanager
def writing(option, path):
    """Turn an OSError raised inside the block (full disk, EIO, removed directory) into
    an InputError naming ``option`` and ``path``."""
    try:
        yield
    except OSError as exc:
        raise InputError(option, os.fspath(path),
                         f"cannot write: {exc.strerror or type(exc).__name__}") from None


def write_text(option, path, text):
    """Write ``text`` (a str, as UTF-8; bytes as they are; or an iterable of bytes-like
    pieces written one after another as they come) to ``path`` whole or not at all
    (``write_pieces``); an OSError becomes an InputError naming ``option``."""
    if isinstance(text, str):
        text = text.encode("utf-8")
    with writing(option, path):
        write_pieces(path, (text,) if isinstance(text, bytes) else text)


def write_pieces(path, pieces):
    """Write the bytes-like ``pieces`` (an iterable: a stream is written as it comes, not
    joined first) to ``path`` whole or not at all: into a new file beside it (``.NAME.PID.part``)
    that then replaces it, so an interrupted or failed write (Ctrl-C, a full disk) leaves
    the file as it was and no part of a document. The file keeps its permissions (a new
    one gets 0o666 less the umask, as ``open`` gives); a symbolic link is written through.
    A path that is not a regular file (/dev/null, a pipe), or one in a directory where no
    file can be made (a writable file in a read-only directory), is written in place."""
    target = Path(os.path.realpath(path))
    if target.exists() and not target.is_file():
        return _write_in_place(target, pieces)
    part = target.with_name(f".{target.name}.{os.getpid()}.part")
    try:
        fd = _create(part)
    except PermissionError:
        return _write_in_place(target, pieces)
    try:
        with os.fdopen(fd, "wb") as f:
            f.writelines(pieces)
        with suppress(FileNotFoundError):
            os.chmod(part, os.stat(target).st_mode & 0o7777)
        if _exchange(part, target):
            os.unlink(part)  # the old file now
        else:
            os.replace(part, target)
    except BaseException:
        with suppress(OSError):
            os.unlink(part)
        raise


RENAME_EXCHANGE = 2  # renameat2's flag (linux/fs.h)
AT_FDCWD = -100  # renameat2's "paths as they are"


def _exchange(a, b):
    """Swap the files at paths ``a`` and ``b`` in one step (Linux's renameat2 with
    RENAME_EXCHANGE); False, nothing changed, where that cannot be done (``b`` does not
    exist, a file system or C library without it: ``os.replace`` then). Why not always
    ``os.replace``: replacing an existing file makes ext4 (auto_da_alloc) start writing the
    new file to disk within the call. Over the previous run's 30 MB of a CoGiRo verify
    (strace): rename 13 - 27 ms, the exchange 0.1 ms and the old file's unlink 8 - 17 ms.
    The data reaches the disk by the kernel's usual writeback, as a new file's does."""
    if not os.path.exists(b):
        return False
    import ctypes  # here: the 3 ms of its import only where an output is replaced
    renameat2 = getattr(ctypes.CDLL(None), "renameat2", None)
    return renameat2 is not None and renameat2(
        AT_FDCWD, os.fsencode(a), AT_FDCWD, os.fsencode(b), RENAME_EXCHANGE) == 0


def _create(path):
    """A new file at ``path`` opened for writing (its descriptor), mode 0o666 less the umask;
    one left there by an earlier process of this pid (killed mid-write) is replaced."""
    flags = os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_NOFOLLOW", 0)
    try:
        return os.open(path, flags, 0o666)
    except FileExistsError:
        os.unlink(path)
        return os.open(path, flags, 0o666)


def _write_in_place(target, pieces):
    with open(target, "wb") as f:
        f.writelines(pieces)


def print_or_write(option, path, text):
    """``text`` on stdout when ``path`` is None, else written to ``path`` (``write_text``)
    with one line saying so: how a command that prints a document (urdf, mjcf) outputs it."""
    if path is None:
        print(text, end="")
    else:
        write_text(option, path, text)
        print(f"wrote {path}")
