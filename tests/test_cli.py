"""usdfacedyn: import/inspect/validate end to end, flags, exit codes and bad input."""
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from pxr import Usd

from facedyn.cli import build_parser, main
from facedyn.usd.take import read_take

from usd_fixtures import grid_mesh, write_mesh_cache


def run(argv, capsys):
    try:
        code = main([str(a) for a in argv])
    except SystemExit as exc:  # argparse's own usage errors
        code = exc.code
    out, err = capsys.readouterr()
    return code, out, err


def test_import_inspect_validate_ict_cache(tmp_path, ict_mesh_cache, capsys):
    cache, frames = ict_mesh_cache
    code, out, err = run(["import", cache, "-o", tmp_path / "capture.usdc", "-q"], capsys)
    assert code == 0, err
    root = tmp_path / "take.usda"
    assert root.is_file() and "wrote" in out
    perf, _ = read_take(root)
    assert perf.points.shape == (24, 11248, 3) and perf.fps == 60.0
    np.testing.assert_allclose(perf.points, frames, atol=1e-5)
    assert perf.uvs is not None and perf.uvs.indices is not None
    code, out, err = run(["inspect", root], capsys)
    assert code == 0 and "capture.usdc" in out and "import" in out and "11248 points" in out
    code, out, err = run(["inspect", root, "--json"], capsys)
    described = json.loads(out)
    assert [l["processor"] for l in described["layers"]] == ["take", "import"]
    assert described["face"]["frames"] == 24
    code, out, err = run(["validate", root], capsys)
    assert code == 0, out
    assert "0 error(s)" in out
    assert Usd.SchemaRegistry().FindAppliedAPIPrimDefinition("FacedynFaceAPI") is not None


def test_frames_json_dry_run_and_attach(tmp_path, grid_cache, capsys):
    cache, frames = grid_cache
    code, out, _ = run(["import", cache, "-o", tmp_path / "dry.usdc", "--dry-run"], capsys)
    assert code == 0 and "would write" in out and not (tmp_path / "dry.usdc").exists()
    code, out, _ = run(["import", cache, "-o", tmp_path / "capture.usdc", "--frames", "1002:1003", "--json"], capsys)
    report = json.loads(out)
    assert code == 0 and report["frame_count"] == 2 and report["frame_range"] == [1002.0, 1003.0]
    perf, _ = read_take(tmp_path / "take.usda")
    np.testing.assert_allclose(perf.points, frames[1:3])
    # An import makes or extends its own root (--root): it does not offer --attach, and a script that passes one is refused.
    code, out, _ = run(["import", "--help"], capsys)
    assert code == 0 and "--attach" not in out and "--root" in out
    code, _, err = run(["import", cache, "-o", tmp_path / "again.usdc", "--attach", tmp_path / "take.usda", "-q"], capsys)
    assert code == 2 and "--attach" in err and not (tmp_path / "again.usdc").exists()
    from facedyn.errors import UsageError
    from facedyn.processors import registry
    from facedyn.processors.base import Request
    from facedyn.processors.runner import execute
    from facedyn.progress import Progress

    with pytest.raises(UsageError, match="takes no --attach"):
        execute(registry.load("import"), Request([cache], tmp_path / "again.usdc", attach=tmp_path / "take.usda"), Progress.silent())
    assert not (tmp_path / "again.usdc").exists()


def test_units_and_up_axis_are_made_canonical(tmp_path, capsys):
    points, counts, indices = grid_mesh(3)
    frames = np.stack([points, points + 1])
    cache = write_mesh_cache(tmp_path / "zup.usda", frames, counts, indices, up_axis="Z", meters_per_unit=1.0)
    code, _, err = run(["import", cache, "-o", tmp_path / "capture.usdc", "-q"], capsys)
    assert code == 0, err
    perf, _ = read_take(tmp_path / "take.usda")
    expected = np.stack([frames[..., 0], frames[..., 2], -frames[..., 1]], axis=-1) * 100.0
    np.testing.assert_allclose(perf.points, expected, atol=1e-4)
    assert perf.meters_per_unit == 0.01 and perf.up_axis == "Y"


def test_parameters_by_flag_and_by_p(tmp_path, grid_cache, capsys):
    cache, _ = grid_cache
    code, _, err = run(["import", cache, "-o", tmp_path / "c.usdc", "-p", "nope=1"], capsys)
    assert code == 2 and "unknown parameter 'nope'" in err
    code, _, err = run(["import", cache, "-o", tmp_path / "c.usdc", "-p", "fps"], capsys)
    assert code == 2 and "KEY=VALUE" in err
    code, _, err = run(["import", cache, "-o", tmp_path / "c.usdc", "--fps", "fast"], capsys)
    assert code == 2 and "expected float" in err
    code, _, err = run(["import", cache, "-o", tmp_path / "c.usdc", "--frames", "9:1"], capsys)
    assert code == 2 and "empty frame range" in err


def _assert_clean_failure(code, err, expected_code, *fragments):
    assert code == expected_code, err
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert "Traceback" not in err
    for fragment in fragments:
        assert fragment in lines[0], lines[0]


def test_bad_inputs_are_one_line_errors_and_leave_nothing(tmp_path, grid_cache, capsys):
    cache, frames = grid_cache
    out = tmp_path / "out"
    out.mkdir()
    target = out / "capture.usdc"

    code, _, err = run(["import", tmp_path / "missing.usd", "-o", target], capsys)
    _assert_clean_failure(code, err, 1, "missing.usd", "no such file")

    junk = tmp_path / "junk.usda"
    junk.write_text("this is not usd\n")
    code, _, err = run(["import", junk, "-o", target], capsys)
    _assert_clean_failure(code, err, 1, "junk.usda", "not a readable USD file")

    code, _, err = run(["import", cache, "-o", target, "--mesh", "/Cache/Nope"], capsys)
    _assert_clean_failure(code, err, 1, "grid_cache.usda", "no prim at /Cache/Nope")

    points, counts, indices = grid_mesh(3)
    still = write_mesh_cache(tmp_path / "still.usda", points[None], counts, indices)
    from pxr import Usd as _Usd

    stage = _Usd.Stage.Open(str(still))
    attr = stage.GetPrimAtPath("/Cache/Geo/Face").GetAttribute("points")
    value = attr.Get(1001)
    attr.Clear()
    attr.Set(value)
    stage.Save()
    code, _, err = run(["import", still, "-o", target, "--mesh", "/Cache/Geo/Face"], capsys)
    _assert_clean_failure(code, err, 1, "still.usda", "no time samples")

    varying = write_mesh_cache(tmp_path / "varying.usda", np.stack([points, points]), counts, indices)
    stage = _Usd.Stage.Open(str(varying))
    topo = stage.GetPrimAtPath("/Cache/Geo/Face").GetAttribute("faceVertexIndices")
    topo.Set(indices, 1001)
    topo.Set(indices[::-1].copy(), 1002)
    stage.Save()
    code, _, err = run(["import", varying, "-o", target], capsys)
    _assert_clean_failure(code, err, 1, "varying.usda", "faceVertexIndices changes at time 1002")

    bad = np.stack([points, points])
    bad[1, 2, 1] = np.nan
    nan_cache = write_mesh_cache(tmp_path / "nan.usda", bad, counts, indices)
    code, _, err = run(["import", nan_cache, "-o", target], capsys)
    _assert_clean_failure(code, err, 1, "nan.usda", "NaN or infinite values at time 1002")

    code, _, err = run(["import", cache, "-o", cache], capsys)
    _assert_clean_failure(code, err, 2, "overwrite an input")

    code, _, err = run(["import", junk, "-o", tmp_path / "nowhere" / "deeper" / "c.usdc"], capsys)
    _assert_clean_failure(code, err, 1, "junk.usda")
    assert not (tmp_path / "nowhere").exists()  # a failed run leaves no folder it made
    code, _, err = run(["import", cache, "-o", tmp_path / "made" / "c.usdc", "-q"], capsys)
    assert code == 0 and (tmp_path / "made" / "c.usdc").is_file() and (tmp_path / "made" / "take.usda").is_file()

    assert list(out.iterdir()) == []


def test_permission_denied_folder(tmp_path, grid_cache, capsys):
    cache, _ = grid_cache
    locked = tmp_path / "locked"
    locked.mkdir()
    locked.chmod(0o500)
    try:
        if os.access(locked, os.W_OK):
            pytest.skip("running as root, who may write into read-only folders (see the /proc case)")
        code, _, err = run(["import", cache, "-o", locked / "c.usdc"], capsys)
        _assert_clean_failure(code, err, 1, "not writable")
    finally:
        locked.chmod(0o700)


def test_unwritable_folder_even_for_root(tmp_path, grid_cache, capsys):
    """Root users bypass permissions; a read-only *file system* location still fails cleanly."""
    cache, _ = grid_cache
    code, _, err = run(["import", cache, "-o", Path("/proc/capture.usdc"), "-q"], capsys)
    _assert_clean_failure(code, err, 1, "/proc")


def test_usage_errors_exit_2(capsys):
    code, _, err = run(["nosuch-command"], capsys)
    _assert_clean_failure(code, err, 2, "usage error", "invalid choice")
    code, _, err = run(["import"], capsys)
    _assert_clean_failure(code, err, 2, "usage error", "required")


def test_version_list_env(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["--version"])
    assert exc.value.code == 0 and "usdfacedyn" in capsys.readouterr().out
    code, out, _ = run(["list"], capsys)
    listed = [line.split()[0] for line in out.splitlines()]
    assert code == 0 and {"import", "stabilize", "remove", "synthesize", "retarget", "preview", "simulate", "synth", "train-removal",
                          "train-synthesis", "demo"} <= set(listed)
    commands = build_parser(["--help"])._subparsers._group_actions[0].choices
    assert sorted(listed) == sorted(commands)  # every command, the tools (inspect, validate, layers, batch, env, list) included
    code, out, _ = run(["env"], capsys)
    assert code == 0 and out.startswith("export PXR_PLUGINPATH_NAME=")


def test_third_party_processor_is_discovered_through_entry_points(tmp_path):
    site = tmp_path / "site"
    (site / "studio_tools").mkdir(parents=True)
    (site / "studio_tools" / "__init__.py").write_text("")
    (site / "studio_tools" / "smooth.py").write_text(
        "from facedyn.processors.base import Parameter, Plan, Processor, Reads, Writes\n"
        "class SmoothProcessor(Processor):\n"
        "    name = 'studio-smooth'\n"
        "    summary = 'a studio-specific smoothing pass'\n"
        "    reads = Reads('take')\n"
        "    writes = Writes('layer', role='quasistatic')\n"
        "    parameters = (Parameter('strength', float, 0.5, 'how much to smooth', minimum=0.0, maximum=1.0),)\n"
        "    def prepare(self, request):\n        return Plan({})\n"
        "    def run(self, plan, progress):\n        raise NotImplementedError\n"
    )
    dist = site / "studio_tools-1.0.dist-info"
    dist.mkdir()
    (dist / "METADATA").write_text("Metadata-Version: 2.1\nName: studio-tools\nVersion: 1.0\n")
    (dist / "entry_points.txt").write_text("[facedyn.processors]\nstudio-smooth = studio_tools.smooth:SmoothProcessor\n")
    env = dict(os.environ, PYTHONPATH=str(site))
    result = subprocess.run([sys.executable, "-m", "facedyn.cli", "list"], capture_output=True, text=True, env=env)
    assert result.returncode == 0, result.stderr
    assert any(line.split(None, 1) == ["studio-smooth", "a studio-specific smoothing pass"] for line in result.stdout.splitlines())
    assert "import" in result.stdout
    result = subprocess.run([sys.executable, "-m", "facedyn.cli", "studio-smooth", "--help"], capture_output=True, text=True, env=env)
    assert result.returncode == 0 and "--attach" in result.stdout and "--dry-run" in result.stdout
    assert "--strength FLOAT" in result.stdout and "(default: 0.5)" in result.stdout
    result = subprocess.run([sys.executable, "-m", "facedyn.cli", "studio-smooth", "t.usda", "-o", "x.usdc", "--strength", "2"],
                            capture_output=True, text=True, env=env)
    assert result.returncode == 2 and "--strength: must be at most 1" in result.stderr


def test_import_obj_sequence(tmp_path, capsys):
    from facedyn.io.obj import ObjMesh, write_obj

    points, counts, indices = grid_mesh(4)
    uv_values = points[:, :2] / 3.0
    folder = tmp_path / "objs"
    folder.mkdir()
    for frame in (1001, 1002, 1010):
        mesh = ObjMesh(points + 0.01 * frame, counts, indices, uv_values, indices.copy())
        write_obj(folder / f"face.{frame}.obj", mesh)
    code, _, err = run(["import", folder, "-o", tmp_path / "capture.usdc", "-q"], capsys)
    _assert_clean_failure(code, err, 2, "--fps")
    code, _, err = run(["import", *sorted(folder.glob("*.obj")), "-o", tmp_path / "capture.usdc", "--fps", "30", "--units", "0.1", "-q"], capsys)
    assert code == 0, err
    perf, _ = read_take(tmp_path / "take.usda")
    # The gap 1003..1009 is filled by interpolation over time (the motion is linear, so exactly).
    np.testing.assert_array_equal(perf.frames, np.arange(1001, 1011))
    np.testing.assert_allclose(perf.points[9], (points + 10.10) * 0.1, atol=1e-5)
    np.testing.assert_allclose(perf.points[5], (points + 10.06) * 0.1, atol=1e-5)
    assert perf.fps == 30.0 and perf.uvs.indices is not None
    # A frame whose topology differs is named in the error.
    write_obj(folder / "face.1011.obj", ObjMesh(points, counts[:-1], indices[:-4]))
    code, _, err = run(["import", folder, "-o", tmp_path / "capture2.usdc", "--fps", "30", "-q"], capsys)
    _assert_clean_failure(code, err, 1, "face.1011.obj")
    assert not (tmp_path / "capture2.usdc").exists()


def _cubic_motion(points, seconds):
    """Points moving along a cubic polynomial in time (reproduced exactly by a cubic spline)."""
    t = np.asarray(seconds, np.float64)[:, None, None]
    return (points[None] + t * np.array([3.0, -1.0, 0.5]) + t**2 * np.array([-2.0, 4.0, 1.0]) + t**3 * np.array([5.0, 0.0, -3.0])).astype(np.float32)


def test_import_fps_resamples_a_capture_onto_whole_frames(tmp_path, capsys):
    points, counts, indices = grid_mesh(3)
    source = write_mesh_cache(tmp_path / "at30.usda", _cubic_motion(points, np.arange(9) / 30.0), counts, indices, fps=30.0)
    code, out, err = run(["import", source, "-o", tmp_path / "capture.usdc", "--fps", "120", "--json"], capsys)
    assert code == 0, err
    assert json.loads(out)["summary"]["source_fps"] == 30.0
    perf, _ = read_take(tmp_path / "take.usda")
    assert perf.fps == 120.0
    np.testing.assert_array_equal(perf.frames, np.arange(1001, 1034))  # 8/30 s at 120 fps, from the source's first frame
    np.testing.assert_allclose(perf.points, _cubic_motion(points, np.arange(33) / 120.0), atol=1e-4)
    np.testing.assert_allclose(perf.points[::4], _cubic_motion(points, np.arange(9) / 30.0), atol=1e-5)


def test_import_refuses_samples_between_frames_unless_resampled(tmp_path, capsys):
    points, counts, indices = grid_mesh(3)
    seconds = np.arange(10) / 120.0
    source = write_mesh_cache(tmp_path / "between.usda", _cubic_motion(points, seconds), counts, indices, fps=24.0)
    stage = Usd.Stage.Open(str(source))
    attr = stage.GetPrimAtPath("/Cache/Geo/Face").GetAttribute("points")
    values = [attr.Get(t) for t in attr.GetTimeSamples()]
    attr.Clear()
    for i, value in enumerate(values):
        attr.Set(value, 1001 + i * 0.2)  # a 120 fps capture authored at 24 time codes/s
    stage.Save()
    code, _, err = run(["import", source, "-o", tmp_path / "capture.usdc"], capsys)
    _assert_clean_failure(code, err, 1, "between.usda", "1001.2 is not a whole frame", "--fps 120")
    assert not (tmp_path / "capture.usdc").exists()
    code, _, err = run(["import", source, "-o", tmp_path / "capture.usdc", "--fps", "120", "-q"], capsys)
    assert code == 0, err
    perf, _ = read_take(tmp_path / "take.usda")
    np.testing.assert_array_equal(perf.frames, np.arange(1001, 1011))
    np.testing.assert_allclose(perf.points, _cubic_motion(points, seconds), atol=1e-5)
    for bad in ("nan", "inf", "-1"):
        code, _, err = run(["import", source, "-o", tmp_path / "bad.usdc", "--fps", bad], capsys)
        assert code == 2 and "--fps" in err


def test_paths_and_degenerate_meshes_are_one_line_errors(tmp_path, grid_cache, capsys, monkeypatch):
    """Issue 16: symlink loops, names that are no USD layer, .usdz outputs, collapsed or astronomically large meshes."""
    cache, frames = grid_cache
    monkeypatch.chdir(tmp_path)
    (tmp_path / "loop1").symlink_to(tmp_path / "loop2")
    (tmp_path / "loop2").symlink_to(tmp_path / "loop1")
    (tmp_path / "noext").write_text("")
    cases = [
        (["import", "loop1", "-o", "c.usdc"], 1, "loop of symbolic links"),
        (["stabilize", "noext", "-o", "s.usdc"], 2, "not a take"),
        (["import", cache, "-o", "c"], 2, "a layer is written as .usdc"),
        (["import", cache, "-o", "c.usdz"], 2, "not .usdz"),
        (["import", cache, "-o", os.fsdecode(b"caf\xe9/capture.usdc")], 1, "not valid UTF-8"),
        (["inspect", os.fsdecode(b"caf\xe9.usda")], 1, "not valid UTF-8"),
    ]
    points, counts, indices = grid_mesh(3)
    for name, values, message in (("zero", np.zeros((2, len(points), 3)), "every point coincides"),
                                  ("huge", np.stack([points, points]) * 1e30, "coordinates beyond")):
        cases.append((["import", write_mesh_cache(tmp_path / f"{name}.usda", values, counts, indices), "-o", f"{name}.usdc"], 1, message))
    for argv, expected, message in cases:
        code, _, err = run(argv, capsys)
        _assert_clean_failure(code, err, expected, message)
    assert sorted(p.name for p in tmp_path.iterdir() if p.name != Path(cache).name) == ["huge.usda", "loop1", "loop2", "noext", "zero.usda"]
