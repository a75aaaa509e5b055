"""`usdfacedyn calibrate` end to end at a tiny scale: a rig, its actor and a session of held
expressions in; the family's F, the actor's response and the chosen removal out, resumable."""
import json

import pytest
import torch

from facedyn.cli import main
from facedyn.dynamics.bands import BandWeights
from facedyn.dynamics.modelfile import load_model, save_blend, save_model
from facedyn.dynamics.spread import spread_of, with_spread
from facedyn.sim.corpus import TakeSpec
from facedyn.sim.default_face import default_face
from facedyn.sim.tissue import TissueParams
from facedyn.processors.corpus_writer import build_corpus
from facedyn.usd.blendshape_rig import write_blendshape_rig

SESSION = [("smile", "platform:6"), ("smile", "walk"), ("jaw_open", "platform:9"), ("jaw_open", "hop")]
TISSUE = TissueParams(soft_hz=6.5, damping_ratio=0.15)  # the actor's own, not the corpus's family


def cli(*argv):
    return main([str(a) for a in argv] + ["-q"])


@pytest.fixture(scope="module")
def actor_session(tmp_path_factory):
    """(rig file, stabilized session take roots): the session captured and stabilized with the rig's actor."""
    torch.set_num_threads(1)
    folder = tmp_path_factory.mktemp("actor")
    rig = default_face(8)
    rig_path = write_blendshape_rig(rig, folder / "rig.usda")
    assert cli("actor", rig_path, "-o", folder / "actor.usda") == 0
    specs = [TakeSpec(f"{e}_{m.replace(':', '')}", m, e, duration_s=2.0, seed=50 + i, tissue=TISSUE, noise_cm=0.002)
             for i, (e, m) in enumerate(SESSION)]
    build_corpus(folder / "session", rig, specs)
    roots = []
    for spec in specs:
        root = folder / "session" / spec.name / "take.usda"
        assert cli("stabilize", root, "-o", root.parent / "stabilized.usdc", "--attach", root, "--actor", folder / "actor.usda") == 0
        roots.append(root)
    return rig_path, roots


@pytest.mark.slow
def test_calibrate_chooses_the_least_leaving_removal_and_resumes(actor_session, tmp_path, capsys):
    rig, roots = actor_session
    out = tmp_path / "actor_models"
    flags = ("--rig", rig, "--corpus-scale", "demo", "--corpus-only", "*_platform[79]hz", "--epochs", "2", "--jobs", "1",
             "--settle", "0.3")
    assert cli("calibrate", *roots, "-o", out, *flags) == 0
    record = json.loads((out / "calibration.json").read_text())
    figures = {name: c["session_motion_left"] for name, c in record["candidates"].items()}
    assert set(figures) == {"family", "response", "mean", "bands"} and all(0 < v < 10 for v in figures.values())
    assert record["chosen"] == min(figures, key=figures.get)
    assert figures["bands"] <= min(figures["family"], figures["response"], figures["mean"])  # the weights include all three
    removal = out / record["removal"]
    assert removal.is_file() and removal.name == {"family": "removal.removal", "response": "removal.response", "mean": "removal.blend",
                                                  "bands": "removal.blend"}[record["chosen"]]
    assert sorted(p.name for p in out.glob("removal.*")) == [removal.name]
    assert (out / "synthesis.response").is_file() and (out / "family.removal").is_file()
    assert record["budget"]["epochs"] == 2 and record["budget"]["epochs_given"] and record["budget"]["budget_minutes"] == 45.0
    assert record["budget"]["training_seconds_planned"] is None  # --epochs pins them: no minutes
    assert record["family"]["epochs"] == 2 and record["family"]["pairs_per_second"] > 0
    assert set(record["stage_seconds"]) == {"corpus", "family", "response", "scores"}
    # the actor's spread, learned on the session, is in the response and in the family's F of every removal calibrate writes
    actor = load_model(out / "synthesis.response")
    spread = actor.info["spread"]
    assert record["response"]["spread"] == spread and spread["session_missed_with_spread"] < spread["session_missed_by_smoothest"]
    assert spread_of(load_model(out / "family.removal")) is None  # the family's own file stays the corpus's
    family = save_model(with_spread(load_model(out / "family.removal"), *spread_of(actor)), tmp_path / "family_spread.removal")
    # the figures are evaluate --session's: the mean's, re-run by hand, is the recorded one
    assert cli("evaluate", *roots, "--session", "true", "--removal", family, "--blend", out / "synthesis.response",
               "-o", tmp_path / "by_hand") == 0
    by_hand = json.loads((tmp_path / "by_hand" / "report.json").read_text())["session"]["motion_left_beyond_sag"]
    assert by_hand == figures["mean"]
    # and the band blend's: its weights applied by evaluate (as remove applies them) leave what the fit said
    bands = save_blend([load_model(family), actor], tmp_path / "bands.blend", BandWeights.from_json(record["candidates"]["bands"]["weights"]))
    assert cli("evaluate", *roots, "--session", "true", "--removal", bands, "-o", tmp_path / "bands_by_hand") == 0
    by_hand = json.loads((tmp_path / "bands_by_hand" / "report.json").read_text())["session"]["motion_left_beyond_sag"]
    assert by_hand == pytest.approx(figures["bands"], abs=2e-4)
    assert cli("remove", roots[1], "--model", bands, "--blend", out / "family.removal", "-o", tmp_path / "refused.usdc") == 2
    assert "weighs its members per frequency band" in capsys.readouterr().err and not (tmp_path / "refused.usdc").exists()
    # the chosen removal is one file remove takes; a network H would not be
    take = roots[1]
    assert cli("remove", take, "--model", removal, "-o", tmp_path / "quasistatic.usdc") == 0
    # a re-run with the same inputs keeps every stage (and its bytes); a changed input redoes what depends on it
    before = {p: p.stat().st_mtime_ns for p in (out / "family.removal", out / "synthesis.response")}
    capsys.readouterr()
    renamed = rig.parent / ".." / rig.parent.name / rig.name  # the same rig named another way
    assert main([str(a) for a in ("calibrate", *roots, "-o", out, "--rig", renamed, *flags[2:])]) == 0
    assert "done before, kept" in capsys.readouterr().err
    assert {p: p.stat().st_mtime_ns for p in before} == before
    assert cli("calibrate", *roots, "-o", out, *flags[:-2], "--settle", "0.4") == 0
    assert (out / "family.removal").stat().st_mtime_ns == before[out / "family.removal"]
    assert (out / "synthesis.response").stat().st_mtime_ns != before[out / "synthesis.response"]


def test_calibrate_refuses_takes_in_another_skull_frame_or_without_a_rig(actor_session, tmp_path, capsys):
    rig, roots = actor_session
    assert cli("calibrate", *roots, "-o", tmp_path / "out") == 2  # --rig is required
    assert cli("calibrate", roots[0], "--rig", rig, "-o", tmp_path / "out") == 2  # one take: nothing to leave out
    other = write_blendshape_rig(default_face(6), tmp_path / "other.usda")
    assert cli("calibrate", *roots, "--rig", other, "-o", tmp_path / "out") != 0
    errors = capsys.readouterr().err
    assert "--rig is required" in errors and "at least two" in errors and "Traceback" not in errors
    assert not (tmp_path / "out").exists()


def test_calibrate_simulates_its_corpus_at_the_session_rate_and_refuses_a_mixed_session(actor_session, tmp_path, capsys):
    """A model serves one rate: the corpus is planned at the session's rate (60 fps captures
    need no resampling), and a session of takes at two rates is refused before anything is built."""
    rig, roots = actor_session
    slow = []
    for k in range(2):
        folder = tmp_path / f"slow{k}"
        assert cli("import", roots[k].parent / "capture.usdc", "-o", folder / "capture.usdc", "--fps", "60") == 0
        assert cli("stabilize", folder / "take.usda", "-o", folder / "stabilized.usdc", "--attach", folder / "take.usda",
                   "--actor", roots[0].parent.parent.parent / "actor.usda") == 0
        slow.append(folder / "take.usda")
    capsys.readouterr()
    assert cli("calibrate", *slow, "--rig", rig, "-o", tmp_path / "planned", "--dry-run", "--json") == 0
    assert json.loads(capsys.readouterr().out)["plan"]["corpus_fps"] == 60
    assert cli("calibrate", slow[0], *roots[1:], "--rig", rig, "-o", tmp_path / "out") == 2
    errors = capsys.readouterr().err
    assert "60, 120 fps" in errors and "--fps" in errors and "Traceback" not in errors
    assert not (tmp_path / "out").exists() and not (tmp_path / "planned").exists()


def test_calibrate_refuses_a_data_folder_that_lacks_what_the_corpus_reads(actor_session, tmp_path, capsys):
    rig, roots = actor_session
    assert cli("calibrate", *roots, "--rig", rig, "--data", tmp_path / "no-such-data", "-o", tmp_path / "out") == 2
    errors = capsys.readouterr().err
    assert "--data" in errors and "no such folder" in errors and "Traceback" not in errors
    assert not (tmp_path / "out").exists()
