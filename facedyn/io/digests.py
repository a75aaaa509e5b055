"""File digests kept across commands, so that a command does not hash again what no one changed.

Every step identifies the layers it reads by their content (facedyn.usd.runs), and checks the
layers below and above it by the same ids: a remove on a 1,000-frame ICT take hashed 700 MB
of layers, a third of its time. A digest is kept under $XDG_CACHE_HOME/facedyn/digests/ (else
~/.cache/facedyn/), one small file per file identity: the path, device, inode, size, and
modification and change times in nanoseconds. Rewriting a file changes its change time (no
tool sets that back) and facedyn's own writes replace the file (a new inode), so a kept
digest is only ever read for the bytes it was computed from.

Timestamps tick coarsely (a jiffy on Linux, a second or two on some network file systems):
a file written twice within one tick to the same size would keep its identity. So a digest
is kept only when the file had not changed for RACY_S before it was hashed and did not
change while it was; a younger file is hashed again by the next command, as before. The
KEEP most recently written digests stay; a cache that cannot be written only costs speed.
Only POSIX systems keep digests: on Windows st_ctime is the file's creation time, which an
in-place rewrite does not change.
"""
from __future__ import annotations

import hashlib
import os
import string
import time
from pathlib import Path
from typing import Callable

from facedyn.io.files import user_cache_folder, write_atomically

KEEP = 4096  # digests kept (about 16 MB of folder entries at most)
RACY_S = 2.0  # a file must have been still this long before its digest is kept
KEEPS = os.name == "posix"  # where st_ctime is the change time (see the module)


def folder() -> Path:
    """Where digests are kept."""
    return user_cache_folder("digests")


def digest(path: Path, compute: Callable[[Path], str]) -> str:
    """compute(path), or the digest kept for this very file when there is one."""
    if not KEEPS:
        return compute(path)
    before = os.stat(path)
    entry = folder() / _entry_name(path, before)
    kept = _read(entry)
    if kept is not None:
        return kept
    value = compute(path)
    if time.time() - max(before.st_mtime, before.st_ctime) > RACY_S and _identity(os.stat(path)) == _identity(before):
        _keep(entry, value)
    return value


def _identity(info: os.stat_result) -> tuple:
    return info.st_dev, info.st_ino, info.st_size, info.st_mtime_ns, info.st_ctime_ns


def _entry_name(path: Path, info: os.stat_result) -> str:
    text = "\0".join(str(part) for part in (Path(path).resolve(), *_identity(info)))
    return hashlib.sha256(text.encode()).hexdigest()[:40]


def _read(entry: Path) -> str | None:
    try:
        value = entry.read_text(encoding="ascii").strip()
    except (OSError, UnicodeDecodeError):
        return None
    return value if value and len(value) <= 64 and all(c in string.hexdigits for c in value) else None


def _keep(entry: Path, value: str) -> None:
    """Write one digest (atomically), then drop the oldest beyond KEEP; failures are ignored."""
    try:
        entry.parent.mkdir(parents=True, exist_ok=True)
        write_atomically(entry, lambda out: out.write(value.encode("ascii")))
        entries = list(os.scandir(entry.parent))
        if len(entries) > KEEP + KEEP // 4:  # pruned in batches: a scan per kept digest, a sort now and then
            entries.sort(key=_modified, reverse=True)
            for stale in entries[KEEP:]:
                Path(stale.path).unlink(missing_ok=True)
    except OSError:
        pass


def _modified(entry: os.DirEntry) -> float:
    try:
        return entry.stat().st_mtime
    except OSError:  # removed by another process meanwhile
        return 0.0
