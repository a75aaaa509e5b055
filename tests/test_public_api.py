"""Each algorithm package states its public names (`__all__`), loads them only when used, and they exist."""
import importlib
import json
import subprocess
import sys

import pytest

PACKAGES = ("facedyn.dynamics", "facedyn.geometry", "facedyn.stabilize", "facedyn.kernels", "facedyn.io", "facedyn.preview",
            "facedyn.usd")
HEAVY = ("torch", "scipy", "pyopencl", "pxr")


@pytest.mark.parametrize("package", PACKAGES)
def test_public_names_are_stated_and_resolve(package):
    module = importlib.import_module(package)
    names = module.__all__
    assert names and names == sorted(set(names)) and not [n for n in names if n.startswith("_")]
    for name in names:
        assert getattr(module, name) is not None, f"{package}.{name}"
    with pytest.raises(AttributeError, match="no attribute 'no_such_name'"):
        getattr(module, "no_such_name")


def test_importing_an_algorithm_package_loads_no_heavy_library():
    code = ("import json, sys\n" + "".join(f"import {p}\n" for p in PACKAGES if p != "facedyn.usd")
            + f"print(json.dumps(sorted({{m.split('.')[0] for m in sys.modules}} & set({HEAVY!r}))))")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert json.loads(done.stdout) == []
