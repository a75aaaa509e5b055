"""usdfacedyn evaluate on simulated takes whose removal is the truth (truth.usda): the report
agrees with the diagnostics on the arrays, a perfect removal passes, and bad input is refused."""
import json

import numpy as np
import pytest

from facedyn.cli import main
from facedyn.dynamics import diagnostics
from facedyn.preview.images import read_image
from facedyn.sim.corpus import TakeSpec
from facedyn.sim.default_face import default_face
from facedyn.processors.corpus_writer import build_corpus
from facedyn.usd.corpus_files import read_truth


def cli(*argv):
    return main([str(a) for a in argv] + ["-q"])


@pytest.fixture(scope="module")
def corpus(tmp_path_factory):
    folder = tmp_path_factory.mktemp("corpus")
    specs = [TakeSpec(f"smile_{m.replace(':', '')}", m, "smile", duration_s=1.5, seed=i) for i, m in enumerate(("platform:8", "walk", "hop"))]
    build_corpus(folder, default_face(12), specs)
    return folder


def test_evaluate_reports_a_true_removal_as_nearly_perfect(corpus, tmp_path):
    roots = [corpus / name / "truth.usda" for name in ("smile_platform8", "smile_walk", "smile_hop")]
    out = tmp_path / "eval"
    assert cli("evaluate", *roots, "-o", out, "--held-expression", "true") == 0
    report = json.loads((out / "report.json").read_text())
    platform = report["takes"][0]
    assert platform["skull_peak_hz"] == pytest.approx(8.0, abs=0.3)
    assert platform["residual_at_frequency"] < 0.05
    spread = report["held_expression"]
    assert spread["per_frame_ratio"] < 0.3
    # the report's numbers are the diagnostics of the arrays it read
    truth = read_truth(corpus / "smile_platform8")
    fv = default_face(12).face_vertices
    expected = diagnostics.residual_at_frequency(truth.points, truth.points + truth.offsets, truth.fps, platform["residual_frequency_hz"], fv)
    assert platform["residual_at_frequency"] == pytest.approx(expected, abs=1e-4)
    pixels, _ = read_image(out / "diagnostics.png")
    assert pixels.shape[:2] == (900, 900) and np.ptp(pixels) > 0


def test_evaluate_refuses_takes_without_removal(corpus, tmp_path, capsys):
    assert cli("evaluate", corpus / "smile_walk" / "take.usda", "-o", tmp_path / "e1") == 1
    assert "run `usdfacedyn remove` first" in capsys.readouterr().err
    assert cli("evaluate", corpus / "smile_walk" / "truth.usda", "-o", tmp_path / "e2", "--held-expression", "true") == 2
    assert "at least two" in capsys.readouterr().err
    assert not (tmp_path / "e1").exists() and not (tmp_path / "e2").exists()


def test_evaluate_refuses_more_frames_than_it_reads_whole_and_takes_a_range(corpus, tmp_path, capsys, monkeypatch):
    import facedyn.processors.evaluate as evaluate

    monkeypatch.setattr(evaluate, "MAX_FRAMES", 100)
    root = corpus / "smile_walk" / "truth.usda"
    assert cli("evaluate", root, "-o", tmp_path / "long") == 2
    assert "evaluate reads at most 100 frames" in capsys.readouterr().err and not (tmp_path / "long").exists()
    from facedyn.usd.frames import TakeFrames

    first = int(TakeFrames(root, "synthesized").time_codes[0])
    assert cli("evaluate", root, "-o", tmp_path / "range", "--frames", f"{first}:{first + 79}") == 0
    assert json.loads((tmp_path / "range" / "report.json").read_text())["takes"][0]["frames"] == 80
