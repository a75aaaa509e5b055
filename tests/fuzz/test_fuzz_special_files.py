"""Paths that name no regular file (FIFOs, devices, sockets, links to them), given to every reader and command.

Each must end at once in a one-line error naming the path: a FIFO would block a reader
until a writer comes, a device would feed it forever. A writer arrives at every FIFO after
30 s, so a regression fails instead of hanging the suite.
"""
import contextlib
import io
import os
import shutil
import socket
import tempfile
import threading
from pathlib import Path

import pytest
from hypothesis import event, given
from hypothesis import strategies as st

from facedyn.cli import main
from facedyn.errors import FacedynError

pytestmark = pytest.mark.skipif(not hasattr(os, "mkfifo") or not hasattr(socket, "AF_UNIX"), reason="FIFOs and sockets are POSIX")

KINDS = ("fifo", "socket", "/dev/null", "/dev/zero", "link to fifo")
SUFFIXES = (".usda", ".usdc", ".usd", ".fdyn", ".bvh", ".obj", ".csv", ".txt", "")


def _reader(name):
    from facedyn.dynamics.modelfile import load_model
    from facedyn.io import bvh, livelink, obj
    from facedyn.usd.source import open_mesh_source
    from facedyn.usd.take import read_take

    return {
        "read_take": read_take, "load_model": load_model, "open_mesh_source": open_mesh_source, "read_bvh": bvh.read_bvh,
        "read_obj": obj.read_obj, "read_livelink_csv": lambda p: livelink.read_livelink_csv(p, ["jawOpen"]),
    }[name]


READERS = ("read_take", "load_model", "open_mesh_source", "read_bvh", "read_obj", "read_livelink_csv")
COMMANDS = ("import", "inspect", "validate", "layers", "stabilize --actor", "remove --model", "batch")


def _special(kind: str, folder: Path, suffix: str) -> Path:
    if kind.startswith("/dev/"):
        return Path(kind)
    path = folder / f"special{suffix}"
    if kind == "socket":
        server = socket.socket(socket.AF_UNIX)
        server.bind(str(path))
        server.close()  # the socket file stays
    else:
        target = folder / f"pipe{suffix}" if kind == "link to fifo" else path
        os.mkfifo(target)
        if kind == "link to fifo":
            path.symlink_to(target)
    return path


def _unblock_later(folder: Path, done: threading.Event) -> None:
    if done.wait(30):
        return
    for path in folder.iterdir():
        try:
            os.close(os.open(path, os.O_WRONLY | os.O_NONBLOCK))
        except OSError:
            pass


def _command(name: str, path: Path, folder: Path) -> list[str]:
    out = str(folder / "out" / "layer.usdc")
    return {
        "import": ["import", str(path), "-o", out], "inspect": ["inspect", str(path)], "validate": ["validate", str(path)],
        "layers": ["layers", str(path)], "stabilize --actor": ["stabilize", str(folder / "t.usda"), "--actor", str(path), "-o", out],
        "remove --model": ["remove", str(folder / "t.usda"), "--model", str(path), "-o", out],
        "batch": ["batch", str(path), "-o", str(folder / "out"), "--steps", "import"],
    }[name]


@given(st.sampled_from(KINDS), st.sampled_from(SUFFIXES), st.sampled_from(READERS + COMMANDS))
def test_special_files_end_in_one_line_naming_them(kind, suffix, user):
    if kind.startswith("/dev/") and not os.path.exists(kind):
        return
    event(f"special: {kind}")
    with tempfile.TemporaryDirectory() as scratch:
        folder = Path(scratch)
        path = _special(kind, folder, suffix)
        done = threading.Event()
        threading.Thread(target=_unblock_later, args=(folder, done), daemon=True).start()
        try:
            if user in READERS:
                with pytest.raises(FacedynError) as error:
                    _reader(user)(path)
                message = str(error.value)
                assert str(path) in message and "\n" not in message, message
            else:
                stderr = io.StringIO()
                with contextlib.redirect_stderr(stderr), contextlib.redirect_stdout(io.StringIO()):
                    try:
                        code = main(_command(user, path, folder))
                    except SystemExit as exc:
                        code = exc.code
                err = stderr.getvalue()
                assert code == 2, err
                assert str(path) in err and len(err.strip().splitlines()) == 1, err
                assert not (folder / "out").exists()
        finally:
            done.set()


@pytest.fixture(scope="module")
def plain_take(tmp_path_factory) -> Path:
    """A take imported from a small mesh cache (capture.usdc and take.usda)."""
    import numpy as np
    from usd_fixtures import grid_mesh, write_mesh_cache

    folder = tmp_path_factory.mktemp("take")
    points, counts, indices = grid_mesh(4)
    cache = write_mesh_cache(folder / "cache.usda", np.stack([points + 0.1 * i for i in range(4)]), counts, indices)
    assert main(["import", str(cache), "-o", str(folder / "take" / "capture.usdc"), "-q"]) == 0
    return folder / "take"


@given(st.sampled_from(KINDS), st.sampled_from([".usdc", ".usda"]), st.sampled_from(["inspect", "validate", "layers", "stabilize"]))
def test_a_take_listing_a_special_file_ends_at_once(plain_take, kind, suffix, command):
    """A sublayer that is a FIFO would block USD's composition forever: readers name it in one line before USD opens it,
    and `layers` (which composes nothing) lists it as unreadable, saying what it is, so it can be detached."""
    from pxr import Sdf

    if kind.startswith("/dev/") and not os.path.exists(kind):
        return
    event(f"sublayer: {kind}")
    with tempfile.TemporaryDirectory() as scratch:
        folder = Path(scratch) / "take"
        shutil.copytree(plain_take, folder)
        path = _special(kind, folder, suffix)
        done = threading.Event()
        threading.Thread(target=_unblock_later, args=(folder, done), daemon=True).start()
        root = Sdf.Layer.OpenAsAnonymous(str(folder / "take.usda"))
        root.subLayerPaths.insert(0, str(path) if kind.startswith("/dev/") else f"./{path.name}")
        root.Export(str(folder / "take.usda"))
        argv = {"stabilize": ["stabilize", str(folder / "take.usda"), "-o", str(folder / "s.usdc")]}.get(command, [command, str(folder / "take.usda")])
        stdout, stderr = io.StringIO(), io.StringIO()
        try:
            with contextlib.redirect_stderr(stderr), contextlib.redirect_stdout(stdout):
                code = main(argv)
        finally:
            done.set()
        err = stderr.getvalue()
        if command == "layers":
            assert code == 0 and err == "", err
            listed = [line.split() for line in stdout.getvalue().splitlines() if line.split() and line.split()[0].endswith(path.name)]
            assert listed and listed[0][-1] == "unreadable", stdout.getvalue()
            what = {"fifo": "a FIFO", "link to fifo": "a FIFO", "socket": "a socket"}.get(kind, "a character device")
            assert f"unreadable: is {what}, not a USD file" in stdout.getvalue(), stdout.getvalue()
        else:
            assert code == 1 and str(path) in err and "not a USD file" in err and len(err.strip().splitlines()) == 1, err
            assert not (folder / "s.usdc").exists()
