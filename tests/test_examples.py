"""examples/: every walkthrough runs, in order, on one work folder, with tiny training.

Each script is run as a user would (`bash examples/NN_name.sh WORK`, `python
examples/07_variant_shot.py WORK`) with 1-epoch networks and a two-take corpus, and must
exit 0 and write its main output. The scripts share the work folder, so later ones reuse
the corpus, models and layers of earlier ones (run alone, each builds what it needs).
"""
from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
BVH = EXAMPLES.parent.parent / "shared" / "data" / "cmu-mocap" / "131_03.bvh"
TAKE, OTHER = "smile_hop", "smile_walk"

# script -> its main outputs, relative to the work folder
SCRIPTS = {
    "01_import.sh": ["imported/capture.usdc", "imported/take.usda"],
    "02_stabilize.sh": [f"corpus/{TAKE}/stabilized.usdc", f"corpus/{TAKE}/three_point.usdc"],
    "03_remove.sh": ["models/face.removal", f"corpus/{TAKE}/quasistatic.usdc"],
    "04_synthesize.sh": ["models/face.synthesis", f"corpus/{TAKE}/synthesized.hop.usdc"]
    + ([f"corpus/{TAKE}/synthesized.cmu131_03.usdc"] if BVH.is_file() else []),
    "05_retarget.sh": [f"corpus/{TAKE}/synthesized.retarget.usdc", f"corpus/{TAKE}/synthesized.delta-transfer.usdc"],
    "06_preview.sh": [f"corpus/{TAKE}/hop.preview.usdc"],
    "07_variant_shot.py": ["shot/shot.usda"],
}


@pytest.fixture(scope="module")
def work(tmp_path_factory) -> Path:
    return tmp_path_factory.mktemp("examples")


def run_example(script: str, work: Path) -> subprocess.CompletedProcess:
    bin_dir = str(Path(sys.executable).parent)  # where pip put usdfacedyn beside this python
    env = dict(
        os.environ,
        PATH=bin_dir + os.pathsep + os.environ.get("PATH", ""),
        PYTHON=sys.executable,
        FACEDYN_EXAMPLE_F_EPOCHS="1",
        FACEDYN_EXAMPLE_H_EPOCHS="1",
        FACEDYN_EXAMPLE_F_SUBSAMPLE="0.25",
        FACEDYN_EXAMPLE_TAKES="smile_[hw]*",  # smile_hop (the take) and smile_walk (the retarget source)
        FACEDYN_EXAMPLE_TAKE=TAKE,
        FACEDYN_EXAMPLE_OTHER=OTHER,
    )
    command = [sys.executable] if script.endswith(".py") else ["bash"]
    return subprocess.run(command + [str(EXAMPLES / script), str(work)], env=env, capture_output=True, text=True, timeout=600)


def test_readme_describes_every_script():
    readme = (EXAMPLES / "README.md").read_text()
    on_disk = sorted(p.name for p in EXAMPLES.iterdir() if p.name[:2].isdigit())
    assert on_disk == sorted(SCRIPTS)
    for script in SCRIPTS:
        assert script in readme


@pytest.mark.slow  # each script runs the CLI; 03-05 train networks
@pytest.mark.parametrize("script", list(SCRIPTS))
def test_example_runs(script, work):
    result = run_example(script, work)
    assert result.returncode == 0, f"{script} exited {result.returncode}\n--- stdout\n{result.stdout[-4000:]}\n--- stderr\n{result.stderr[-4000:]}"
    for output in SCRIPTS[script]:
        assert (work / output).is_file(), f"{script} did not write {output}\n{result.stdout[-4000:]}"
    if script == "02_stabilize.sh":
        assert "mode-pursuit" in result.stdout and "three-point" in result.stdout
    if script == "06_preview.sh":
        assert "PXR_PLUGINPATH_NAME" in result.stdout and "usdview" in result.stdout
    if script == "07_variant_shot.py":
        rows = re.findall(r"^(captured|stabilized|quasistatic|synthesized) +\( *-?\d", result.stdout, re.MULTILINE)
        assert sorted(rows) == ["captured", "quasistatic", "stabilized", "synthesized"], result.stdout
        assert "muted: True" in result.stdout
