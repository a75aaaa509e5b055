"""calibrate's budget for F (facedyn.processors.budget): epochs from a throughput measured by a
probe, scaled to the corpus; pure arithmetic, no training."""
import io

import pytest

from facedyn.processors.budget import EpochClock, planned_epochs, probe_rates, probe_takes
from facedyn.processors.calibrate import F_SAMPLES, F_SHARE, MAX_EPOCHS, training_budget
from facedyn.progress import Progress


def test_probe_takes_spread_over_the_corpus_and_keep_a_small_one_whole():
    names = [f"t{i:03d}" for i in range(100)]
    picked = probe_takes(names, 5)
    assert picked == ["t000", "t025", "t050", "t074", "t099"]  # first, last and evenly between, in order
    assert probe_takes(names[:3], 5) == names[:3]


def test_probe_rates_split_the_fixed_part_from_the_epochs():
    # 100 s in all: two epochs of 20 s (the first timed from the start, so it held 30 s of store) and 60 s fixed
    rates = probe_rates(100.0, [50.0, 20.0], frames=1000, pairs_per_frame=172.0)
    assert rates["epoch_seconds"] == 20.0
    assert rates["fixed_seconds_per_frame"] == pytest.approx(0.06) and rates["epoch_seconds_per_frame"] == pytest.approx(0.02)
    assert rates["pairs_per_second"] == pytest.approx(1000 * 172 / 20)
    with pytest.raises(ValueError, match="two timed epochs"):
        probe_rates(10.0, [5.0], 1000, 172.0)


def test_planned_epochs_fill_the_time_left_at_the_probes_speed():
    probe = probe_rates(100.0, [50.0, 20.0], frames=1000, pairs_per_frame=172.0)
    # a corpus 10x the probe: 600 s fixed, 200 s an epoch; 2,000 s fit 7 epochs (600 + 7 * 200 = 2,000)
    plan = planned_epochs(2000.0, probe, 10_000, MAX_EPOCHS)
    assert plan["epochs"] == 7 and plan["predicted_training_seconds"] == pytest.approx(2000.0)
    assert planned_epochs(1999.0, probe, 10_000, MAX_EPOCHS)["epochs"] == 6
    assert planned_epochs(10.0, probe, 10_000, MAX_EPOCHS)["epochs"] == 1  # always one
    assert planned_epochs(1e9, probe, 10_000, MAX_EPOCHS)["epochs"] == MAX_EPOCHS


def test_training_budget_gives_fs_share_of_what_is_left_or_the_epochs_given():
    params = {"budget_minutes": 45.0, "epochs": None, "subsample": 0.5}
    corpus = {"frames": 10_000}
    probe = probe_rates(100.0, [50.0, 20.0], frames=1000, pairs_per_frame=F_SAMPLES * 0.5)
    budget = training_budget(params, corpus, 700.0, probe)
    assert budget["training_seconds_planned"] == pytest.approx(F_SHARE * (2700 - 700))
    assert budget["epochs"] == planned_epochs(F_SHARE * 2000, probe, 10_000, MAX_EPOCHS)["epochs"] == 3
    assert budget["pairs"] == 10_000 * F_SAMPLES and not budget["epochs_given"] and budget["probe"] == probe
    over = training_budget(params, corpus, 5000.0, probe)  # the corpus spent the whole budget: one epoch
    assert over["training_seconds_planned"] == 0 and over["epochs"] == 1
    given = training_budget({**params, "epochs": 12}, corpus, 700.0, None)
    assert given["epochs"] == 12 and given["epochs_given"] and given["probe"] is None


def test_epoch_clock_times_only_the_training_task_and_passes_everything_on():
    stream = io.StringIO()
    inner = Progress(stream, interactive=False)
    clock = EpochClock(inner)
    clock.start("load takes", 3)
    clock.advance()
    assert clock.epoch_seconds() == []  # not a training task
    clock.start("train F (12 takes)", 3)
    for _ in range(3):
        clock.advance()
    clock.finish()
    clock.advance()  # after the task: not an epoch
    seconds = clock.epoch_seconds()
    assert len(seconds) == 3 and all(s >= 0 for s in seconds)
    assert "train F (12 takes): 3/3" in stream.getvalue() and "load takes" in stream.getvalue()
