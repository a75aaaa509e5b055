"""`usdfacedyn simulate` (once `synth`): --data must hold what it is for, the old name still
runs with a note, and a resumable folder keeps what an interrupted run completed."""
import json
from pathlib import Path

import pytest

from facedyn.cli import main
from facedyn.processors.base import FolderOutput, Plan, Processor, Reads, Request, Writes
from facedyn.processors.runner import execute
from facedyn.progress import Progress


def cli(*argv):
    return main([str(a) for a in argv] + ["-q"])


@pytest.mark.parametrize("command", ["simulate", "demo"])
def test_a_missing_data_folder_is_a_usage_error_naming_what_was_expected(tmp_path, command, capsys):
    assert cli(command, "-o", tmp_path / "out", "--data", tmp_path / "no-such-data") == 2
    err = capsys.readouterr().err
    assert "--data" in err and "no-such-data: no such folder" in err and "livelink-face/" in err and "cmu-mocap/" in err
    assert not (tmp_path / "out").exists()


def test_a_data_folder_without_the_protocols_files_is_a_usage_error_naming_them(tmp_path, capsys):
    data = tmp_path / "data"
    (data / "livelink-face").mkdir(parents=True)
    (data / "livelink-face" / "MySlate_3_Jason_Millers_iPhone.csv").write_text("")
    assert cli("simulate", "-o", tmp_path / "out", "--data", data, "--scale", "demo") == 2
    assert "missing cmu-mocap/131_01.bvh, cmu-mocap/131_03.bvh" in capsys.readouterr().err
    assert cli("simulate", "-o", tmp_path / "out", "--data", data / "livelink-face" / "MySlate_3_Jason_Millers_iPhone.csv") == 2
    assert "not a folder" in capsys.readouterr().err


def test_the_old_name_runs_the_same_command_with_a_deprecation_note(tmp_path, capsys):
    assert cli("synth", "-o", tmp_path / "old", "--scale", "demo", "--only", "smile_still", "--jobs", "1") == 0
    assert "`synth` is deprecated" in capsys.readouterr().err
    assert cli("simulate", "-o", tmp_path / "old", "--scale", "demo", "--only", "smile_still", "--jobs", "1") == 0
    assert "deprecated" not in capsys.readouterr().err
    index = json.loads((tmp_path / "old" / "corpus.json").read_text())
    assert index["resumed"] == 1 and [t["name"] for t in index["takes"]] == ["smile_still"]  # the same recipe: kept
    assert cli("simulate", "-o", tmp_path / "old", "--scale", "demo", "--only", "smile_still", "--seed", "5") == 1
    assert "smile_still: a take simulated with another recipe (it differs in spec.seed)" in capsys.readouterr().err
    assert json.loads((tmp_path / "old" / "corpus.json").read_text()) == index  # refused: the corpus as it was


class Interrupted(Processor):
    """Completes one part of its folder, then is interrupted."""

    name = "interrupted"
    reads = Reads("nothing")

    def __init__(self, resumable: bool):
        self.writes = Writes("folder", resumable=resumable)

    def prepare(self, request: Request) -> Plan:
        return Plan({}, request)

    def run(self, plan: Plan, progress: Progress) -> FolderOutput:
        (plan.state.output / "part1").mkdir(parents=True)
        raise KeyboardInterrupt


@pytest.mark.parametrize("resumable", [True, False])
def test_an_interrupted_resumable_folder_keeps_its_completed_parts(tmp_path, resumable):
    output = tmp_path / "new" / "folder"
    with pytest.raises(KeyboardInterrupt):
        execute(Interrupted(resumable), Request([], output), Progress.silent())
    assert (output / "part1").is_dir() == resumable and Path(tmp_path / "new").exists() == resumable
