"""A wheel install (not only the editable checkout) finds the USD plugins through the package."""
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def test_wheel_install_registers_the_schemas(tmp_path):
    wheels = tmp_path / "wheels"
    build = subprocess.run(
        [sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "-q", "-w", str(wheels), str(REPO)],
        capture_output=True, text=True,
    )
    assert build.returncode == 0, build.stderr
    wheel = next(wheels.glob("facedyn-*.whl"))
    venv = tmp_path / "venv"
    subprocess.run([sys.executable, "-m", "venv", "--system-site-packages", str(venv)], check=True)
    python = venv / "bin" / "python"
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
