"""`simulate --soft-hz LOW-HIGH`: the randomized tissue is drawn from that band, the corpus says so,
and a malformed band or one without randomized tissue is a one-line usage error."""
import json

import pytest

from facedyn.cli import main


def cli(*argv):
    return main([str(a) for a in argv] + ["-q"])


@pytest.mark.slow  # simulates a randomized corpus
def test_simulate_draws_tissue_from_the_given_band_and_records_it(tmp_path):
    assert cli("simulate", "-o", tmp_path / "c", "--scale", "demo", "--only", "smile_platform*", "--randomize-tissue", "take",
               "--soft-hz", "6-6.5", "--jobs", "1", "--seed", "3") == 0
    index = json.loads((tmp_path / "c" / "corpus.json").read_text())
    assert index["description"]["soft_hz"] == "6-6.5"
    drawn = [t["spec"]["tissue"]["soft_hz"] for t in index["takes"]]
    assert len(drawn) >= 2 and all(6.0 <= hz <= 6.5 for hz in drawn) and len(set(drawn)) == len(drawn)


@pytest.mark.parametrize("flags, message", [
    (("--randomize-tissue", "take", "--soft-hz", "9-7"), "--soft-hz '9-7': expected a band"),
    (("--randomize-tissue", "take", "--soft-hz", "fast"), "--soft-hz 'fast': expected a band"),
    (("--soft-hz", "7-9"), "add --randomize-tissue"),
])
def test_a_bad_band_is_a_usage_error(tmp_path, capsys, flags, message):
    assert cli("simulate", "-o", tmp_path / "c", "--only", "smile_platform*", *flags) == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err
    assert not (tmp_path / "c").exists()
