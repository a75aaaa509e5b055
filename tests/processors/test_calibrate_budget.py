"""calibrate's budget for F: its share of the minutes the corpus left, and the clock of its
epochs (facedyn.processors.epoch_clock); no training."""
import io

import pytest

from facedyn.processors.epoch_clock import EpochClock
from facedyn.processors.calibrate import F_SAMPLES, MAX_EPOCHS, RESERVE_MIN_S, RESERVE_S_PER_POINT_FRAME, training_budget
from facedyn.progress import Progress


def test_training_budget_gives_f_what_the_corpus_left_less_a_reserve_sized_by_the_session_or_the_epochs_given():
    params = {"budget_minutes": 45.0, "epochs": None, "subsample": 0.5}
    corpus = {"frames": 10_000}
    session = 70 * 540 * 2735  # the 70-take session of the ARKit rig: its point-frames
    budget = training_budget(params, corpus, 700.0, session)
    assert budget["reserve_seconds"] == pytest.approx(RESERVE_S_PER_POINT_FRAME * session, abs=0.1) and budget["reserve_seconds"] > 400
    assert budget["training_seconds_planned"] == pytest.approx(2700 - 700 - budget["reserve_seconds"], abs=0.1)
    assert budget["epochs"] == MAX_EPOCHS and not budget["epochs_given"]  # the minutes stop it, at most the paper's epochs
    assert budget["pairs"] == 10_000 * F_SAMPLES
    small = training_budget(params, corpus, 700.0, 6 * 120 * 4058)  # six 2 s takes: the floor
    assert small["reserve_seconds"] == RESERVE_MIN_S and small["training_seconds_planned"] == 2700 - 700 - RESERVE_MIN_S
    over = training_budget(params, corpus, 5000.0, session)  # the corpus spent the whole budget: a second, so one epoch
    assert over["training_seconds_planned"] == 1.0
    given = training_budget({**params, "epochs": 12}, corpus, 700.0, session)
    assert given["epochs"] == 12 and given["epochs_given"] and given["training_seconds_planned"] is None


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
