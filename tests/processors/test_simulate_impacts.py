"""`simulate --impacts`: every gait take of the corpus jolts at its foot contacts, and the corpus says so."""
import json

import numpy as np
import pytest

from facedyn.cli import main
from facedyn.usd.corpus_files import read_truth


def cli(*argv):
    return main([str(a) for a in argv] + ["-q"])


@pytest.mark.slow  # simulates a gait take with and without jolts
def test_simulate_impacts_jolts_the_gait_takes_and_records_it(tmp_path):
    for name, flag in (("smooth", "false"), ("jolted", "true")):
        assert cli("simulate", "-o", tmp_path / name, "--scale", "demo", "--only", "smile_walk", "--impacts", flag, "--jobs", "1") == 0
    smooth = json.loads((tmp_path / "smooth" / "corpus.json").read_text())
    jolted = json.loads((tmp_path / "jolted" / "corpus.json").read_text())
    assert smooth["description"]["impacts"] is False and jolted["description"]["impacts"] is True
    assert [t["spec"]["impacts"] for t in jolted["takes"]] == [True]
    a, b = read_truth(tmp_path / "smooth" / "smile_walk"), read_truth(tmp_path / "jolted" / "smile_walk")
    jolt = np.abs(b.skull_translate - a.skull_translate).max()
    assert 0.01 < jolt < 2.0  # cm: the same walk, with jolts on it
