"""Start-up: looking at the command line loads none of the heavy libraries.

`usdfacedyn --version`, `--help`, `list` and a command's `--help` parse arguments and print;
SciPy, PyTorch, pyopencl and USD (each 0.2-4 s to import) must load only when a command's
work needs them (issue 40). Checked on the modules a fresh interpreter holds afterwards,
not on a clock, so the test holds on a loaded machine.
"""
import json
import subprocess
import sys

import pytest

HEAVY = ("torch", "scipy", "pyopencl", "pxr")

PROBE = """
import contextlib, io, json, sys
import facedyn.cli
with contextlib.redirect_stdout(io.StringIO()):
    try:
        code = facedyn.cli.main(sys.argv[1:])
    except SystemExit as exit:
        code = exit.code
print(json.dumps({"code": code, "modules": sorted(m for m in sys.modules if m.split(".")[0] in %r)}))
""" % (HEAVY,)


def loaded_after(*argv: str) -> dict:
    done = subprocess.run([sys.executable, "-c", PROBE, *argv], capture_output=True, text=True, check=True)
    return json.loads(done.stdout.strip().splitlines()[-1])


@pytest.mark.parametrize("argv", [("--version",), ("--help",), ("list",), ("stabilize", "--help"), ("remove", "--help")])
def test_looking_at_the_command_line_loads_no_heavy_library(argv):
    result = loaded_after(*argv)
    assert result["code"] == 0
    assert result["modules"] == [], f"usdfacedyn {' '.join(argv)} imported {sorted({m.split('.')[0] for m in result['modules']})}"


def test_a_usage_error_loads_no_heavy_library():
    result = loaded_after("stabilize", "take.usda")  # -o missing
    assert result["code"] == 2 and result["modules"] == []


def test_a_command_that_runs_still_loads_usd(tmp_path):
    result = loaded_after("validate", str(tmp_path / "missing.usda"))
    assert result["code"] == 1 and "pxr" in result["modules"]
