"""Digests kept across commands: reused for the very same file, never for changed bytes."""
import hashlib
import os
import time

import pytest

from facedyn.io import digests


@pytest.fixture
def cache(monkeypatch, tmp_path):
    """An empty digest cache, and files counted as still long enough to keep (no waiting in tests)."""
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    monkeypatch.setattr(digests, "RACY_S", -1.0)
    return tmp_path


class Hasher:
    """sha256 of a file, counting its calls."""

    def __init__(self):
        self.calls = 0

    def __call__(self, path):
        self.calls += 1
        return hashlib.sha256(path.read_bytes()).hexdigest()[:16]


def test_a_file_is_hashed_once_across_commands(cache):
    path = cache / "layer.usdc"
    path.write_bytes(b"first bytes")
    first, later = Hasher(), Hasher()
    assert digests.digest(path, first) == hashlib.sha256(b"first bytes").hexdigest()[:16]
    assert digests.digest(path, later) == hashlib.sha256(b"first bytes").hexdigest()[:16]
    assert (first.calls, later.calls) == (1, 0)


def test_changed_bytes_are_hashed_again_even_with_the_old_size_and_times(cache):
    path = cache / "layer.usdc"
    path.write_bytes(b"first bytes")
    before = path.stat()
    digests.digest(path, Hasher())
    time.sleep(0.05)  # a timestamp tick later (within one, RACY_S keeps nothing: the next test)
    path.write_bytes(b"other bytes")  # same size, written in place
    os.utime(path, ns=(before.st_atime_ns, before.st_mtime_ns))  # mtime set back; the change time cannot be
    again = Hasher()
    assert digests.digest(path, again) == hashlib.sha256(b"other bytes").hexdigest()[:16] and again.calls == 1


def test_a_replaced_file_is_hashed_again(cache):
    path, other = cache / "layer.usdc", cache / "new.usdc"
    path.write_bytes(b"first bytes")
    digests.digest(path, Hasher())
    other.write_bytes(b"other bytes")
    os.replace(other, path)  # how facedyn writes: a new file renamed over the old
    again = Hasher()
    assert digests.digest(path, again) == hashlib.sha256(b"other bytes").hexdigest()[:16] and again.calls == 1


def test_a_file_changed_just_now_is_not_kept(cache, monkeypatch):
    monkeypatch.setattr(digests, "RACY_S", 3600.0)  # within a timestamp tick, a same-size rewrite could keep its identity
    path = cache / "layer.usdc"
    path.write_bytes(b"first bytes")
    digests.digest(path, Hasher())
    again = Hasher()
    digests.digest(path, again)
    assert again.calls == 1
    assert not digests.folder().exists() or not any(digests.folder().iterdir())


def test_a_damaged_entry_or_an_unwritable_cache_only_costs_a_hash(cache, monkeypatch):
    path = cache / "layer.usdc"
    path.write_bytes(b"first bytes")
    digests.digest(path, Hasher())
    for entry in digests.folder().iterdir():
        entry.write_text("not a digest\n")
    again = Hasher()
    assert digests.digest(path, again) == hashlib.sha256(b"first bytes").hexdigest()[:16] and again.calls == 1
    blocker = cache / "blocked"
    blocker.write_text("a file where the cache folder would be")
    monkeypatch.setenv("XDG_CACHE_HOME", str(blocker))
    third = Hasher()
    assert digests.digest(path, third) == hashlib.sha256(b"first bytes").hexdigest()[:16] and third.calls == 1


def test_only_the_most_recent_digests_stay(cache, monkeypatch):
    monkeypatch.setattr(digests, "KEEP", 4)
    for k in range(8):
        path = cache / f"layer{k}.usdc"
        path.write_bytes(b"x" * (k + 1))
        digests.digest(path, Hasher())
    kept = [p for p in digests.folder().iterdir() if not p.name.startswith(".")]
    assert 4 <= len(kept) <= 5  # pruned to KEEP once KEEP + KEEP // 4 is passed
