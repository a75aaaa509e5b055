"""Building a corpus folder: a take that fails is skipped and recorded, an interrupted corpus
resumes from its complete takes, a take of another recipe is refused (facedyn.usd.corpus_files)."""
import json
from dataclasses import replace

import pytest

from facedyn.errors import FacedynError
from facedyn.sim.corpus import TakeSpec
from facedyn.sim.default_face import default_face
from facedyn.processors.corpus_writer import build_corpus
from facedyn.usd.corpus_files import CORPUS_INDEX, TAKE_RECIPE
from facedyn.usd.training_data import take_roots

DEAD_PID = 2**22 + 7  # above Linux's pid_max: no process has it


@pytest.fixture(scope="module")
def rig():
    return default_face(resolution=10)


def specs():
    return [TakeSpec("a_walk", "walk", "jaw_open", duration_s=0.25, seed=1), TakeSpec("b_hop", "hop", duration_s=0.25, seed=2)]


def stamp(path):
    stat = path.stat()
    return stat.st_ino, stat.st_mtime_ns


def test_an_interrupted_corpus_resumes_from_its_complete_takes(tmp_path, rig):
    out = tmp_path / "corpus"
    first = build_corpus(out, rig, specs()[:1])
    assert first["resumed"] == 0 and (out / "a_walk" / TAKE_RECIPE).is_file()
    kept = stamp(out / "a_walk" / "capture.usdc")
    half = out / f".b_hop.partial-{DEAD_PID}"  # what a run killed while writing b_hop leaves
    half.mkdir()
    (half / "capture.usdc").write_bytes(b"half a layer")
    index = build_corpus(out, rig, specs())
    assert index["resumed"] == 1 and [t["name"] for t in index["takes"]] == ["a_walk", "b_hop"] and index["failed"] == []
    assert stamp(out / "a_walk" / "capture.usdc") == kept  # not simulated again
    assert not half.exists() and sorted(p.name for p in out.iterdir()) == ["a_walk", "b_hop", CORPUS_INDEX]
    again = build_corpus(out, rig, specs())
    assert again["resumed"] == 2 and again["takes"] == index["takes"]
    assert json.loads((out / CORPUS_INDEX).read_text())["takes"] == index["takes"]


def test_the_same_data_by_another_path_is_the_same_recipe(tmp_path, rig, shared_data):
    csv = shared_data / "livelink-face" / "facial.csv"
    link = tmp_path / "elsewhere.csv"
    link.symlink_to(csv)
    spec = TakeSpec("dialog_facial_still", "still", dialog=str(csv), duration_s=0.25, seed=4)
    build_corpus(tmp_path / "c", rig, [spec])
    assert build_corpus(tmp_path / "c", rig, [replace(spec, dialog=str(tmp_path / ".." / tmp_path.name / "elsewhere.csv"))])["resumed"] == 1


def test_a_complete_take_of_another_recipe_is_refused_or_redone(tmp_path, rig):
    out = tmp_path / "corpus"
    build_corpus(out, rig, specs()[:1])
    kept = stamp(out / "a_walk" / "capture.usdc")
    with pytest.raises(FacedynError, match=r"a_walk: a take simulated with another recipe \(it differs in spec.seed\)"):
        build_corpus(out, rig, [replace(specs()[0], seed=9)], other_recipes="refuse")
    with pytest.raises(FacedynError, match="differs in rig"):
        build_corpus(out, default_face(resolution=11), specs()[:1], other_recipes="refuse")
    assert stamp(out / "a_walk" / "capture.usdc") == kept
    redone = build_corpus(out, rig, [replace(specs()[0], seed=9)])  # the default: simulated again, replaced
    assert redone["resumed"] == 0 and redone["takes"][0]["spec"]["seed"] == 9
    assert json.loads((out / "a_walk" / TAKE_RECIPE).read_text())["recipe"]["spec"]["seed"] == 9


def test_a_take_folder_without_a_recipe_is_simulated_again(tmp_path, rig):
    out = tmp_path / "corpus"
    (out / "a_walk").mkdir(parents=True)
    (out / "a_walk" / "take.usda").write_text("#usda 1.0\n")  # an older facedyn's, or a broken, take
    index = build_corpus(out, rig, specs()[:1])
    assert index["resumed"] == 0 and (out / "a_walk" / TAKE_RECIPE).is_file() and (out / "a_walk" / "truth.usda").is_file()


def test_a_failing_take_is_skipped_and_recorded_and_the_others_are_written(tmp_path, rig):
    out = tmp_path / "corpus"
    broken = TakeSpec("c_dialog", "still", dialog=str(tmp_path / "missing.csv"), duration_s=0.25, seed=3)
    index = build_corpus(out, rig, [specs()[0], broken, specs()[1]], jobs=2)
    assert [t["name"] for t in index["takes"]] == ["a_walk", "b_hop"]
    assert [f["name"] for f in index["failed"]] == ["c_dialog"] and "missing.csv" in index["failed"][0]["error"]
    assert json.loads((out / CORPUS_INDEX).read_text())["failed"] == index["failed"]
    assert not (out / "c_dialog").exists() and not list(out.glob(".*"))
    assert [p.name for p in take_roots([out])] == ["a_walk", "b_hop"]  # the trainers read the written takes only


def test_a_corpus_of_which_no_take_succeeds_is_an_error_and_no_index(tmp_path, rig):
    out = tmp_path / "corpus"
    broken = TakeSpec("c_dialog", "still", dialog=str(tmp_path / "missing.csv"), duration_s=0.25, seed=3)
    with pytest.raises(FacedynError, match="no take could be simulated; c_dialog: .*missing.csv"):
        build_corpus(out, rig, [broken])
    assert not (out / CORPUS_INDEX).exists()
