"""Safe input files (regular files only, bounded, any 8-bit encoding) and atomic writes."""
import os
import stat

import pytest

from facedyn.io import bvh, livelink, obj
from facedyn.io.errors import InputError
from facedyn.io.files import open_regular, read_lines, read_text, write_atomically

READERS = {
    "bvh": bvh.read_bvh,
    "obj": obj.read_obj,
    "csv": lambda path: livelink.read_livelink_csv(path, ["jawOpen"]),
}

posix_only = pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="FIFOs are POSIX")


@posix_only
@pytest.mark.parametrize("reader", sorted(READERS))
def test_a_fifo_is_refused_without_blocking(tmp_path, reader):
    """Opening a FIFO for reading blocks until a writer comes; nobody writes to this one."""
    fifo = tmp_path / f"pipe.{reader}"
    os.mkfifo(fifo)
    with pytest.raises(InputError) as error:
        READERS[reader](fifo)
    assert str(error.value) == f"{fifo}: is not a regular file (a device, FIFO or socket), expected a file"


@pytest.mark.parametrize("reader", sorted(READERS))
def test_devices_folders_and_missing_files_are_named(tmp_path, reader):
    if os.path.exists("/dev/zero"):  # endless: reading it would fill the memory
        with pytest.raises(InputError, match="^/dev/zero: is not a regular file"):
            READERS[reader]("/dev/zero")
    with pytest.raises(InputError, match=f"^{tmp_path}: is a folder, expected a file$"):
        READERS[reader](tmp_path)
    with pytest.raises(InputError, match="absent: no such file$"):
        READERS[reader](tmp_path / "absent")


def test_size_cap_and_decoding(tmp_path):
    path = tmp_path / "notes.txt"
    path.write_bytes("caf\u00e9\n".encode("utf-8"))
    assert read_text(path) == "caf\u00e9\n"
    path.write_bytes("caf\u00e9\n".encode("latin-1"))  # b"caf\xe9": not UTF-8
    assert read_text(path) == "caf\u00e9\n"
    path.write_bytes(b"\xef\xbb\xbfbom\n")
    assert read_text(path) == "bom\n"
    path.write_bytes(bytes(range(256)))  # any bytes decode, as Latin-1
    assert len(read_text(path)) == 256
    path.write_bytes(b"x" * 2049)
    with pytest.raises(InputError, match="notes.txt: is 2049 bytes, more than the 2048 bytes facedyn reads"):
        read_text(path, max_bytes=2048)
    handle, size = open_regular(path)
    with handle:
        assert size == 2049 and handle.read(3) == b"xxx"


def test_lines_split_only_at_line_ends(tmp_path):
    path = tmp_path / "lines.txt"
    path.write_bytes(b"one\r\ntwo\rthree\x85 still three\x0c and here\nfour")
    assert read_lines(path) == ["one", "two", "three\x85 still three\x0c and here", "four"]
    path.write_bytes(b"a\n\nb\n")
    assert read_lines(path) == ["a", "", "b"]


def test_atomic_writes_get_ordinary_permissions_and_leave_nothing_behind(tmp_path):
    target = tmp_path / "out.bin"
    old = os.umask(0o022)
    try:
        write_atomically(target, lambda out: out.write(b"first"))
        assert stat.S_IMODE(target.stat().st_mode) == 0o644

        def fails(out):
            out.write(b"partial")
            raise RuntimeError("disk full")

        with pytest.raises(RuntimeError, match="disk full"):
            write_atomically(target, fails)
    finally:
        os.umask(old)
    assert target.read_bytes() == b"first"  # the old file is untouched
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.bin"]
