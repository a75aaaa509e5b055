"""Opening input files safely and writing output files atomically.

Every reader in facedyn goes through `open_regular` (and text readers through `read_text`),
so every input gets the same guards: only regular files are read (a FIFO would block
forever, /dev/zero would never end), their size is capped, and text is UTF-8 with a
Latin-1 fallback (older exporters write Latin-1 joint names and comments), so a decoding
error is never what a user sees. Writers use `write_atomically`: a temporary file beside
the target, renamed over it, with the permissions an ordinary new file gets (0644 under
the usual umask), so a failed write never leaves a partial or hidden file behind.
"""
from __future__ import annotations

import hashlib
import os
import stat
import tempfile
from collections.abc import Callable
from os import PathLike
from pathlib import Path
from typing import BinaryIO

from facedyn.io.errors import InputError

MAX_TEXT_BYTES = 1 << 30
"""The largest text input read (1 GiB: an hour of 120 fps full-body BVH is about 300 MB)."""


def open_regular(path: str | PathLike) -> tuple[BinaryIO, int]:
    """(binary file object, size in bytes) of a regular file; InputError for anything else.

    The file is opened without blocking and checked on the open descriptor, so a FIFO,
    a device or a folder is refused before a single byte is read.
    """
    try:
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0))
    except FileNotFoundError:
        raise InputError(path, "no such file") from None
    except IsADirectoryError:
        raise InputError(path, "is a folder, expected a file") from None
    except OSError as exc:
        raise InputError(path, f"cannot read: {exc.strerror}") from None
    info = os.fstat(fd)
    if not stat.S_ISREG(info.st_mode):
        os.close(fd)
        what = "a folder" if stat.S_ISDIR(info.st_mode) else "not a regular file (a device, FIFO or socket)"
        raise InputError(path, f"is {what}, expected a file")
    return os.fdopen(fd, "rb"), info.st_size


def special_file_kind(path: str | PathLike) -> str | None:
    """What a path names when it is neither a regular file nor a folder ("a FIFO", ...), else None.

    Only the path's status is looked at (stat follows symbolic links, never opens), so this
    is safe to ask before any reader opens the path: opening a FIFO blocks until a writer
    comes, and a device may never end. A path that does not exist is None: its reader says so.
    """
    try:
        mode = os.stat(path).st_mode
    except (OSError, ValueError):
        return None
    if stat.S_ISREG(mode) or stat.S_ISDIR(mode):
        return None
    kinds = ((stat.S_ISFIFO, "a FIFO"), (stat.S_ISCHR, "a character device"), (stat.S_ISBLK, "a block device"),
             (stat.S_ISSOCK, "a socket"))
    return next((kind for test, kind in kinds if test(mode)), "not a regular file")


def check_not_special(path: str | PathLike, flag: str = "") -> None:
    """UsageError (naming `flag` when given) if `path` is a FIFO, device or socket; see special_file_kind."""
    kind = special_file_kind(path)
    if kind is not None:
        from facedyn.errors import UsageError

        where = f"{flag} {path}" if flag else str(path)
        raise UsageError(f"{where}: is {kind}, not a regular file; facedyn reads only files (and folders where one is expected)")


def read_text(path: str | PathLike, max_bytes: int = MAX_TEXT_BYTES) -> str:
    """A text file's contents: UTF-8 (a byte-order mark is dropped), else Latin-1."""
    handle, size = open_regular(path)
    with handle:
        if size > max_bytes:
            raise InputError(path, f"is {_size(size)}, more than the {_size(max_bytes)} facedyn reads")
        try:
            data = handle.read(max_bytes + 1)
        except OSError as exc:
            raise InputError(path, f"cannot read: {exc.strerror}") from None
    if len(data) > max_bytes:  # grew while being read
        raise InputError(path, f"is more than the {_size(max_bytes)} facedyn reads")
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError:
        return data.decode("latin-1")


def read_lines(path: str | PathLike, max_bytes: int = MAX_TEXT_BYTES) -> list[str]:
    """A text file's lines (see read_text), split only at \\n, \\r\\n and \\r.

    Unlike str.splitlines, control characters such as form feed or U+0085 (a Latin-1
    byte 0x85) do not start a line, so line numbers in errors match what an editor shows.
    """
    text = read_text(path, max_bytes).replace("\r\n", "\n").replace("\r", "\n")
    lines = text.split("\n")
    return lines[:-1] if lines[-1] == "" else lines


def write_atomically(path: str | PathLike, write: Callable[[BinaryIO], None]) -> Path:
    """Call ``write(file)`` on a temporary file beside `path`, then rename it over `path`.

    The file gets the mode of an ordinary new file under the process's umask; whatever
    goes wrong, the temporary file is removed and an existing `path` is left as it was.
    """
    path = Path(path)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as out:
            write(out)
        os.chmod(tmp, _new_file_mode())
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)
    return path


def _size(count: int) -> str:
    return f"{count / 2**20:.0f} MiB" if count >= 2**20 else f"{count} bytes"


def _new_file_mode() -> int:
    """The permission bits an ordinary new file gets under this process's umask (0644 under 022)."""
    mask = os.umask(0)
    os.umask(mask)
    return 0o666 & ~mask


def user_cache_folder(*parts: str) -> Path:
    """facedyn's folder under $XDG_CACHE_HOME (else ~/.cache), joined with parts: what a later run may reuse."""
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base, "facedyn", *parts)


def sha256_of_file(path: str | PathLike, block: int = 1 << 22) -> str:
    """The sha256 (hex) of a file's bytes, streamed a block at a time: never the whole file in memory."""
    digest = hashlib.sha256()
    with open(path, "rb") as handle:
        for chunk in iter(lambda: handle.read(block), b""):
            digest.update(chunk)
    return digest.hexdigest()
