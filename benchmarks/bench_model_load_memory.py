"""Peak memory of loading a model file against the arrays it declares (issue 39's target: at most 4x).

What is measured. For each case a removal model (random weights, sizes consistent with its
metadata) is saved, then loaded by `load_model` in fresh subprocesses, each with
facedyn.dynamics.modelfile (numpy, torch) already imported. A load's peak is the rise of
the process's peak resident memory (VmHWM, reset to the current resident set through
/proc/self/clear_refs just before the load) over the resident set before it.

The first use of torch and numpy in a process also faults in library code and sets up
allocator state, a one-time cost of a few MiB that does not grow with the file. The figures
keep it apart:

- ``first_use_mib``: the peak of loading the smallest model (an 80-point face, 0.25 MiB of
  arrays) first in a process: almost all of it that one-time cost (``first_use_file_backed_mib``
  of it is library code read from disk);
- ``load_peak_mib``: the peak of then loading the case's model in that process (the small
  model kept alive, so its freed memory cannot hide the new load's; a load of less than what
  the interpreter has freed before may still reuse that and show less than its arrays);
- ``first_load_peak_mib``: the peak of loading the case's model first in a process of its own,
  the one-time cost included, as a one-off command sees it.

``ratio`` = load_peak_mib / the declared arrays: the figure the target (<= 4) is about;
``first_load_ratio`` is first_load_peak_mib over the same, the one-time cost included.

    python benchmarks/bench_model_load_memory.py [--out benchmarks/results/model_load_memory.json]
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

from harness import Recorder, parser

CASES = {  # name: (mesh side (side x side points), hidden widths, skin samples)
    "F, 80-point face": (9, (128, 128), 12),
    "F, 11k-point mesh": (106, (128, 128), 344),
    "F, 11k-point mesh, 2048-wide": (106, (2048, 2048), 344),
    "F, 40k-point mesh, 4096-wide": (200, (4096, 4096), 344),
}
WARM_UP = "F, 80-point face"
TARGET_RATIO = 4.0


def build(path: Path, side: int, hidden: tuple[int, ...], samples: int) -> int:
    """Save the case's model at `path`; return the bytes of its declared arrays."""
    import numpy as np
    import torch

    from facedyn.dynamics.face import FaceSetup
    from facedyn.dynamics.modelfile import DynamicsModel, read_model_file, save_model
    from facedyn.dynamics.network import Network, NetworkSpec
    from facedyn.performance import Topology

    ys, xs = np.mgrid[0:side, 0:side].astype(np.float64)
    points = np.stack([xs.ravel(), ys.ravel(), 0.02 * (xs.ravel() - side / 2) ** 2], axis=1)
    quads = [[r * side + c, r * side + c + 1, (r + 1) * side + c + 1, (r + 1) * side + c] for r in range(side - 1) for c in range(side - 1)]
    topology = Topology(np.full(len(quads), 4, np.int32), np.asarray(quads, np.int32).ravel())
    face = FaceSetup.build(topology, points, rigid_vertices=np.arange(2 * side), sample_count=samples)
    torch.manual_seed(0)
    network = Network(NetworkSpec(len(face.landmarks) * 21 * 3 + 63, hidden, 3))
    save_model(DynamicsModel("removal", network, face, 120.0, {"skull": 10, "skin": 10, "target": 10}, {}), path)
    _, arrays = read_model_file(path)
    return sum(a.nbytes for a in arrays.values())


def _status() -> dict[str, float]:
    """This process's VmRSS, VmHWM and RssFile in MiB."""
    found = {}
    for line in Path("/proc/self/status").read_text().splitlines():
        key = line.split(":", 1)[0]
        if key in ("VmRSS", "VmHWM", "RssFile"):
            found[key] = int(line.split()[1]) / 1024
    return found


def _peak_of_load(path: str) -> tuple[dict, object]:
    """(the load's peak rise and its file-backed rise in MiB, the model loaded)."""
    from facedyn.dynamics.modelfile import load_model

    Path("/proc/self/clear_refs").write_text("5")  # VmHWM := VmRSS
    before = _status()
    model = load_model(path)
    after = _status()
    return {"peak": round(after["VmHWM"] - before["VmRSS"], 2), "file_backed": round(after["RssFile"] - before["RssFile"], 2)}, model


def measure(path: str, warm_up: str | None) -> None:
    """In this process: load `warm_up` (if given), then `path`; print their peaks as JSON."""
    import facedyn.dynamics.modelfile  # noqa: F401  (imported before any figure: imports are not the load)

    result, kept = {}, None
    if warm_up:
        result["warm_up"], kept = _peak_of_load(warm_up)
    result["load"], model = _peak_of_load(path)
    del kept, model
    print(json.dumps(result))


def _run(*argv: str) -> dict:
    done = subprocess.run([sys.executable, __file__, *argv], capture_output=True, text=True)
    if done.returncode != 0:
        raise SystemExit(f"measuring {argv} failed: {done.stderr.strip()[-2000:]}")
    return json.loads(done.stdout.strip().splitlines()[-1])


def main() -> None:
    args_parser = parser(__doc__)
    args_parser.add_argument("--measure", help=argparse.SUPPRESS)
    args_parser.add_argument("--warm-up", help=argparse.SUPPRESS)
    args = args_parser.parse_args()
    if args.measure:
        measure(args.measure, args.warm_up)
        return
    with tempfile.TemporaryDirectory(prefix="facedyn-bench-model-load-") as folder, Recorder("bench_model_load_memory", args) as record:
        paths, declared = {}, {}
        for index, (name, (side, hidden, samples)) in enumerate(CASES.items()):
            paths[name] = Path(folder) / f"model{index}.removal"
            declared[name] = build(paths[name], side, hidden, samples)
        for name, path in paths.items():
            warm = _run("--measure", str(path), "--warm-up", str(paths[WARM_UP]))
            first = _run("--measure", str(path))["load"]
            arrays_mib = declared[name] / 2**20
            record({"case": name, "file_mib": round(path.stat().st_size / 2**20, 2), "declared_arrays_mib": round(arrays_mib, 2),
                    "first_use_mib": warm["warm_up"]["peak"], "first_use_file_backed_mib": warm["warm_up"]["file_backed"],
                    "load_peak_mib": warm["load"]["peak"], "ratio": round(warm["load"]["peak"] / arrays_mib, 2),
                    "first_load_peak_mib": first["peak"], "first_load_ratio": round(first["peak"] / arrays_mib, 2),
                    "target_ratio": TARGET_RATIO, "meets_target": warm["load"]["peak"] <= TARGET_RATIO * arrays_mib})


if __name__ == "__main__":
    main()
