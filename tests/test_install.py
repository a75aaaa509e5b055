"""A wheel install (not only the editable checkout) finds the USD plugins through the package.

The wheel goes into a fresh virtual environment that sees the running interpreter's
packages (pxr, numpy...) but not its facedyn: a `.pth` file lists the running environment's
site-packages after the new one's own, so this works whether the tests run from a virtual
environment or a system interpreter (`venv --system-site-packages` alone would only see the
base interpreter's packages). The test is skipped, saying why, where no wheel can be built
offline (no `wheel`/new enough setuptools in the running environment).
"""
import re
import site
import subprocess
import sys
import sysconfig
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]


def _build_wheel(wheels: Path) -> Path:
    build = subprocess.run(
        [sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "-q", "-w", str(wheels), str(REPO)],
        capture_output=True, text=True,
    )
    if build.returncode != 0:
        errors = [line.strip() for line in build.stderr.splitlines() if "error:" in line and not re.search(r"error: [\w-]+$", line)]
        reason = errors[0] if errors else build.stderr.strip()[-200:]
        pytest.skip(f"cannot build a wheel offline in this environment ({reason})")
    return next(wheels.glob("facedyn-*.whl"))


def _venv_seeing_this_environment(venv: Path) -> Path:
    """A new virtual environment whose imports fall back to the running interpreter's site-packages."""
    subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True)
    python = venv / "bin" / "python"
    purelib = subprocess.run([str(python), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
                             capture_output=True, text=True, check=True).stdout.strip()
    running = dict.fromkeys([*site.getsitepackages(), sysconfig.get_paths()["purelib"], sysconfig.get_paths()["platlib"]])
    (Path(purelib) / "running_environment.pth").write_text("".join(f"{p}\n" for p in running if Path(p).is_dir()))
    return python


def test_wheel_install_registers_the_schemas(tmp_path):
    wheel = _build_wheel(tmp_path / "wheels")
    venv = tmp_path / "venv"
    python = _venv_seeing_this_environment(venv)
    install = subprocess.run([str(python), "-m", "pip", "install", "-q", "--no-deps", str(wheel)], capture_output=True, text=True)
    assert install.returncode == 0, install.stderr
    code = (
        "import facedyn, pathlib; from facedyn.usd.plugin import plugin_root; from pxr import Usd\n"
        "root = plugin_root(); print(pathlib.Path(facedyn.__file__).resolve()); print(root)\n"
        "assert Usd.SchemaRegistry().FindAppliedAPIPrimDefinition('FacedynFaceAPI').GetPropertyNames()\n"
    )
    result = subprocess.run([str(python), "-c", code], capture_output=True, text=True, cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    package_file, plugins = result.stdout.split()
    assert str(venv) in package_file and str(venv) in plugins, result.stdout
    assert (Path(plugins) / "facedynSchemas" / "resources" / "generatedSchema.usda").is_file()
