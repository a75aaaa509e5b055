"""--include/--exclude select training takes by any of several comma-separated glob patterns."""
from facedyn.processors.training_inputs import _matches


def test_any_of_the_comma_separated_patterns_selects_a_take():
    assert _matches("dialog_walk", "dialog_walk,dialog_hop")
    assert _matches("dialog_hop", "dialog_walk, dialog_hop")
    assert not _matches("dialog_speech_walk", "dialog_walk,dialog_hop")
    assert _matches("dialog_speech_walk", "smile_*,dialog*")
    assert not _matches("smile_walk", ",")
