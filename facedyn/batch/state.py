"""Whether a batch step is already done: its key, the take's state file, the layer's provenance.

A step's key is a checksum over what the step does (facedyn's version, its command line)
and what it reads (the checksums of the capture or model files it names, and the key of
the step before it, so a changed capture makes every later step stale). A step that
succeeded records its key in the take's state file OUTDIR/<take>/.batch.json, together
with the capture's checksum. The step is current when its output exists, the state file
holds the same key, and the take's layer stack holds the output with the provenance of
this step and this facedyn version (`layer_matches`, the one comparison with what the
layer says).
"""
from __future__ import annotations

import hashlib
import json
import os
import tempfile
from pathlib import Path

import facedyn
from facedyn.batch.plan import StepPlan
from facedyn.io.files import sha256_of_file

STATE_FILE = ".batch.json"


def file_checksum(path: Path) -> str:
    """sha256 of the file's bytes."""
    return sha256_of_file(path)


def input_checksums(plan: StepPlan) -> dict[str, str]:
    """{input path: its checksum} of the files the step reads besides the take (OSError if one is missing)."""
    return {str(path): file_checksum(path) for path in plan.inputs}


def step_key(plan: StepPlan, checksums: dict[str, str], previous_key: str | None) -> str:
    recipe = {"facedyn": facedyn.__version__, "argv": list(plan.argv), "inputs": checksums, "previous": previous_key}
    return hashlib.sha256(json.dumps(recipe, sort_keys=True).encode()).hexdigest()


def read_state(folder: Path) -> dict:
    """The take's state file, or an empty state when there is none (or it is unreadable)."""
    try:
        state = json.loads((Path(folder) / STATE_FILE).read_text())
    except (OSError, ValueError):
        return {"steps": {}}
    return state if isinstance(state.get("steps"), dict) else {"steps": {}}


def record_step(plan: StepPlan, key: str, checksums: dict[str, str], seconds: float) -> None:
    """Write the step's key (and, for the step that reads the capture, its checksum) into the state file, atomically."""
    state = read_state(plan.folder)
    state["steps"][plan.step] = {"key": key, "output": plan.output.name, "argv": list(plan.argv), "seconds": round(seconds, 3),
                                 "facedyn": facedyn.__version__}
    if plan.reads_capture:
        capture = str(plan.inputs[0])
        state["capture"] = {"path": capture, "sha256": checksums[capture]}
    fd, tmp = tempfile.mkstemp(prefix=".batch.", suffix=".json", dir=plan.folder)
    with os.fdopen(fd, "w") as f:
        json.dump(state, f, indent=2, sort_keys=True)
    os.replace(tmp, plan.folder / STATE_FILE)


def is_current(plan: StepPlan, key: str) -> bool:
    """Whether the step's output is there, made by this very step (key) and attached to the take."""
    recorded = read_state(plan.folder)["steps"].get(plan.step, {})
    if recorded.get("key") != key or not plan.output.is_file() or not plan.root.is_file():
        return False
    from facedyn.usd.inspect import describe_take

    try:
        layers = describe_take(plan.root)["layers"]
    except Exception:  # an unreadable take is not current: the step reruns and reports what is wrong
        return False
    output = plan.output.resolve()
    return any(Path(layer["layer"]).resolve() == output and layer_matches(layer, plan) for layer in layers)


def layer_matches(layer: dict, plan: StepPlan) -> bool:
    """Whether a layer's recorded provenance (facedyn.usd.inspect's layer entry) is this step's, by this facedyn."""
    return layer.get("processor") == plan.step and str(layer.get("version", "")).startswith(f"facedyn {facedyn.__version__}")
