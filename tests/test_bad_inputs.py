"""What a bad-input sweep found (issue 39): special files, broken units and rates, flags a source
cannot honour, internal errors, leftovers. Each is one line, exit 1 or 2, and leaves nothing."""
import os
import subprocess
import sys
import threading
from pathlib import Path

import numpy as np
import pytest
from pxr import Sdf

from facedyn.cli import main
from facedyn.errors import FacedynError, UsageError

from cli_run import run
from usd_fixtures import grid_mesh, write_mesh_cache

posix_only = pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="FIFOs are POSIX")


def one_line(code, err, expected_code, *fragments):
    assert code == expected_code, err
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err, err
    for fragment in fragments:
        assert fragment in err, err


@pytest.fixture
def fifo(tmp_path):
    """make(name) -> a FIFO no one writes to; should a reader block on it, a writer comes after 30 s
    (the reader then sees an empty file), so a regression fails instead of hanging."""
    made = []

    def make(name):
        path = tmp_path / name
        os.mkfifo(path)
        made.append(path)
        return path

    stop = threading.Event()

    def unblock():
        if stop.wait(30):
            return
        for path in made:
            try:
                os.close(os.open(path, os.O_WRONLY | os.O_NONBLOCK))
            except OSError:
                pass

    thread = threading.Thread(target=unblock, daemon=True)
    thread.start()
    yield make
    stop.set()


def small_take(tmp_path, name="t"):
    points, counts, indices = grid_mesh()
    frames = np.stack([points + np.array([0.1 * i, 0.0, 0.05 * i], np.float32) for i in range(5)])
    cache = write_mesh_cache(tmp_path / f"{name}_cache.usda", frames, counts, indices)
    assert main(["import", str(cache), "-o", str(tmp_path / name / "capture.usdc"), "-q"]) == 0
    return tmp_path / name / "take.usda"


@posix_only
def test_special_files_are_usage_errors_before_any_reader_opens_them(tmp_path, fifo, capsys):
    out = tmp_path / "o"
    pipe_usdc, pipe_usda = fifo("f.usdc"), fifo("f.usda")
    code, _, err = run(["import", pipe_usdc, "-o", out / "capture.usdc"], capsys)
    one_line(code, err, 2, f"{pipe_usdc}: is a FIFO, not a regular file")
    for command in ("inspect", "validate", "layers"):
        code, _, err = run([command, pipe_usda], capsys)
        one_line(code, err, 2, f"{pipe_usda}: is a FIFO")
    if os.path.exists("/dev/null"):
        code, _, err = run(["import", "/dev/null", "-o", out / "capture.usdc"], capsys)
        one_line(code, err, 2, "/dev/null: is a character device, not a regular file")
    take = small_take(tmp_path)
    for flags, named in ((["--model", pipe_usdc], "--model"), (["--model", tmp_path / "m", "--blend", pipe_usdc], "--blend")):
        code, _, err = run(["remove", take, "-o", take.parent / "q.usdc", *flags], capsys)
        one_line(code, err, 2, f"{named} {pipe_usdc}: is a FIFO")
    code, _, err = run(["stabilize", take, "-o", take.parent / "s.usdc", "--actor", pipe_usda], capsys)
    one_line(code, err, 2, f"--actor {pipe_usda}: is a FIFO")
    code, _, err = run(["stabilize", take, "-o", pipe_usdc], capsys)
    one_line(code, err, 2, f"-o {pipe_usdc}: is a FIFO")
    code, _, err = run(["batch", fifo("shots.txt"), "-o", out, "--steps", "import"], capsys)
    one_line(code, err, 2, "shots.txt: is not a regular file")
    code, _, err = run(["batch", pipe_usdc, "-o", out, "--steps", "import"], capsys)
    one_line(code, err, 2, "f.usdc: is a FIFO")
    assert not out.exists()


@posix_only
def test_a_take_listing_a_fifo_is_refused_before_usd_opens_it(tmp_path, fifo, capsys):
    take = small_take(tmp_path)
    pipe = fifo("t/stabilized.usdc")
    root = Sdf.Layer.FindOrOpen(str(take))
    root.subLayerPaths.insert(0, "./stabilized.usdc")
    root.Save()
    for command in (["inspect", take], ["validate", take], ["stabilize", take, "-o", tmp_path / "t" / "s2.usdc"]):
        code, _, err = run(command, capsys)
        one_line(code, err, 1, f"{take}: names {pipe}, which is a FIFO, not a USD file")


def test_a_truncated_layer_of_a_take_is_named(tmp_path, capsys):
    take = small_take(tmp_path)
    damaged = take.parent / "stabilized.usdc"
    data = (take.parent / "capture.usdc").read_bytes()
    damaged.write_bytes(data[: len(data) // 2])
    root = Sdf.Layer.FindOrOpen(str(take))
    root.subLayerPaths.insert(0, "./stabilized.usdc")
    root.Save()
    for command in ("validate", "inspect"):
        code, _, err = run([command, take], capsys)
        one_line(code, err, 1, f"names {damaged}, which is not a readable USD file (damaged or truncated?)")
    code, out, err = run(["layers", take], capsys)  # it listed the damaged layer as a plain layer, "ok"
    assert code == 0 and err == "", err
    assert [line.split()[-1] for line in out.splitlines() if line.startswith("./")] == ["unreadable", "ok"], out
    assert "unreadable: not a readable USD file (damaged or truncated?)" in out


def test_a_text_layer_cut_short_is_unreadable_though_its_metadata_reads(tmp_path, capsys):
    """A .usda cut in its body still has a readable header: layers showed it ok while validate refused the take."""
    take = small_take(tmp_path)
    text = take.parent / "stabilized.usda"
    Sdf.Layer.FindOrOpen(str(take.parent / "capture.usdc")).Export(str(text))
    text.write_bytes(text.read_bytes()[: -len(text.read_bytes()) // 3])
    root = Sdf.Layer.FindOrOpen(str(take))
    root.subLayerPaths.insert(0, "./stabilized.usda")
    root.Save()
    code, _, err = run(["validate", take], capsys)
    one_line(code, err, 1, f"names {text}, which is not a readable USD file")
    code, out, err = run(["layers", take], capsys)
    assert code == 0 and [line.split()[-1] for line in out.splitlines() if line.startswith("./")] == ["unreadable", "ok"], out


@pytest.mark.parametrize("field, value, written", [
    ("timeCodesPerSecond", 0.0, "0"), ("timeCodesPerSecond", -24.0, "-24"), ("framesPerSecond", 0.0, "0"),
    ("metersPerUnit", 0.0, "0"), ("metersPerUnit", -1.0, "-1"), ("metersPerUnit", float("nan"), "nan"),
    ("metersPerUnit", float("inf"), "inf"),
])
def test_units_and_rates_must_be_finite_and_positive_on_import(tmp_path, capsys, field, value, written):
    """0 collapsed every point, -1 mirrored the face, a rate of 0 left a broken take.usda: refused before anything is written."""
    points, counts, indices = grid_mesh()
    frames = np.stack([points + np.array([0.1 * i, 0.0, 0.0], np.float32) for i in range(4)])
    source = write_mesh_cache(tmp_path / "src.usda", frames, counts, indices)
    layer = Sdf.Layer.FindOrOpen(str(source))
    crate = Sdf.Layer.CreateNew(str(tmp_path / "src.usdc"))  # a crate file keeps what the text parser would refuse
    crate.TransferContent(layer)
    if field == "metersPerUnit":
        crate.pseudoRoot.SetInfo("metersPerUnit", value)
    else:
        setattr(crate, field, value)
    crate.Save()
    out = tmp_path / "out"
    code, _, err = run(["import", tmp_path / "src.usdc", "-o", out / "capture.usdc"], capsys)
    one_line(code, err, 1, f"src.usdc: {field} is {written}; it must be a finite number above 0")
    assert not out.exists()


def test_validate_and_readers_refuse_a_take_whose_rate_is_zero(tmp_path, capsys):
    take = small_take(tmp_path)
    root = Sdf.Layer.FindOrOpen(str(take))
    bad = Sdf.Layer.CreateNew(str(tmp_path / "t" / "zero.usdc"))
    bad.TransferContent(root)
    bad.timeCodesPerSecond = 0.0
    bad.Save()
    for command in (["validate", bad.realPath], ["inspect", bad.realPath], ["stabilize", bad.realPath, "-o", tmp_path / "t" / "s.usdc"]):
        code, _, err = run(command, capsys)  # a rate of 0 made USD map every frame onto one time code: refused before composing
        one_line(code, err, 1, "zero.usdc: timeCodesPerSecond is 0; it must be a finite number above 0")


def test_flags_a_source_cannot_honour_are_usage_errors(tmp_path, grid_cache, capsys):
    cache, _ = grid_cache
    code, _, err = run(["import", cache, "-o", tmp_path / "o" / "c.usdc", "--units", "100"], capsys)
    one_line(code, err, 2, "--units applies to OBJ sequences", "grid_cache.usda is USD")
    folder = tmp_path / "objs"
    folder.mkdir()
    for i in range(3):
        (folder / f"f.{i + 1}.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    code, _, err = run(["import", folder, "-o", tmp_path / "o" / "c.usdc", "--fps", "30", "--mesh", "/A"], capsys)
    one_line(code, err, 2, "--mesh picks a prim in a USD source")
    assert not (tmp_path / "o").exists()
    from facedyn.processors.motion_source import skull_motion

    with pytest.raises(UsageError, match="--bvh-units: BVH conventions, but the skull motion 'walk' is not a BVH file"):
        skull_motion("walk", 120.0, 10, bvh={"units": 5.0})


def test_a_cuda_device_this_torch_cannot_use_is_named(capsys, tmp_path):
    import torch

    from facedyn.dynamics.network import resolve_device
    from facedyn.processors.base import check_device

    if torch.cuda.is_available():
        count = torch.cuda.device_count()
        assert check_device("cuda") is None
        assert f"no cuda:{count}" in check_device(f"cuda:{count}")
        return
    assert check_device("cuda").startswith("CUDA is not available in this torch")
    with pytest.raises(FacedynError, match="--device cuda:0: CUDA is not available in this torch"):
        resolve_device("cuda:0")
    code, _, err = run(["remove", tmp_path / "t.usda", "--model", tmp_path / "m", "-o", tmp_path / "q.usdc", "--device", "cuda"], capsys)
    one_line(code, err, 2, "--device: CUDA is not available in this torch")


def test_a_closed_stdout_pipe_ends_quietly():
    """`usdfacedyn list | head -0`: the reader is gone before anything is written."""
    process = subprocess.Popen([sys.executable, "-m", "facedyn.cli", "list"], stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    process.stdout.close()
    err = process.stderr.read().decode()
    assert process.wait(timeout=120) == 141 and err == ""


def test_a_failed_import_leaves_no_root_no_lock_and_no_folder(tmp_path, capsys, monkeypatch):
    """A fault after the take root is created (here: the attach itself) removes the root, its lock file and the folders made."""
    from facedyn.usd import rootedit

    def attach_then_fail(*args, **kwargs):
        real_attach(*args, **kwargs)
        raise OSError(28, "No space left on device")

    real_attach = rootedit._attach
    monkeypatch.setattr(rootedit, "_attach", attach_then_fail)
    points, counts, indices = grid_mesh()
    cache = write_mesh_cache(tmp_path / "c.usda", np.stack([points, points + 0.1]), counts, indices)
    code, _, err = run(["import", cache, "-o", tmp_path / "new" / "take" / "capture.usdc", "-q"], capsys)
    one_line(code, err, 1, "No space left on device")
    assert not (tmp_path / "new").exists()
    monkeypatch.undo()
    take = small_take(tmp_path)  # a root that was there before a failure stays
    before = sorted(p.name for p in take.parent.iterdir())
    monkeypatch.setattr(rootedit, "_attach", attach_then_fail)
    code, _, err = run(["stabilize", take, "-o", take.parent / "stabilized.usdc", "--attach", take, "-q"], capsys)
    assert code == 1 and take.is_file() and sorted(p.name for p in take.parent.iterdir()) == before


def test_a_late_fault_in_a_long_import_leaves_nothing(tmp_path, capsys):
    """A NaN after the first chunk is found while the layer streams (the root lock taken): nothing stays."""
    points, counts, indices = grid_mesh(3)
    frames = np.stack([points + np.float32(0.001 * i) for i in range(1100)])
    frames[1050, 2] = np.nan
    cache = write_mesh_cache(tmp_path / "late.usdc", frames, counts, indices)
    code, _, err = run(["import", cache, "-o", tmp_path / "out" / "sub" / "capture.usdc", "-q"], capsys)
    one_line(code, err, 1, "NaN or infinite values at time 2051")
    assert not (tmp_path / "out").exists()


def test_failed_batch_takes_leave_no_folders(tmp_path):
    from facedyn.batch.plan import Models, plan_take
    from facedyn.batch.steps import execute_step

    missing = tmp_path / "gone.usdc"
    plans = plan_take("gone", missing, tmp_path / "batch", ("import",), Models())
    result = execute_step(plans[0], None)
    assert result["status"] == "failed" and "gone.usdc" in result["error"]
    assert not (tmp_path / "batch" / "gone").exists()


def test_a_source_without_an_extension_is_named(tmp_path, grid_cache, capsys):
    """USD's format registry raised on an empty extension (as on /dev/null)."""
    cache, _ = grid_cache
    bare = tmp_path / "capture"
    bare.write_bytes(Path(cache).read_bytes())
    code, _, err = run(["import", bare, "-o", tmp_path / "o" / "c.usdc"], capsys)
    one_line(code, err, 1, f"{bare}: not a USD file (unknown extension '')")
    assert not (tmp_path / "o").exists()
