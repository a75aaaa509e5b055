"""Peak memory of loading a model file against the arrays it declares (issue 39's target: at most 4x).

For each case a removal model (random weights, sizes consistent with its metadata) is saved,
then loaded in a fresh subprocess whose peak resident memory is reset (/proc/self/clear_refs)
just before `load_model`; the rise of the peak (VmHWM) over the resident memory before the
load is the load's peak (the first load's, and a second's, without the first use's fixed
costs). One JSON object per case:

    python benchmarks/bench_model_load_memory.py
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

CASES = {  # name: (mesh side (side x side points), hidden widths)
    "F, 11k-point mesh": (106, (128, 128)),
    "F, 11k-point mesh, 2048-wide": (106, (2048, 2048)),
    "F, 40k-point mesh, 4096-wide": (200, (4096, 4096)),
}


def build(path: Path, side: int, hidden: tuple[int, ...]) -> int:
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
    face = FaceSetup.build(topology, points, rigid_vertices=np.arange(2 * side), sample_count=344)
    torch.manual_seed(0)
    network = Network(NetworkSpec(len(face.landmarks) * 21 * 3 + 63, hidden, 3))
    save_model(DynamicsModel("removal", network, face, 120.0, {"skull": 10, "skin": 10, "target": 10}, {}), path)
    _, arrays = read_model_file(path)
    return sum(a.nbytes for a in arrays.values())


def measure(path: str) -> None:
    """In this process: the peak rise of loading the model at `path` (MiB), printed as JSON."""
    from facedyn.dynamics.modelfile import frame_bytes, load_model

    def status(key: str) -> float:
        line = next(l for l in Path("/proc/self/status").read_text().splitlines() if l.startswith(key + ":"))
        return int(line.split()[1]) / 1024

    peaks = []
    for _ in range(2):  # the first load also pays for torch's and numpy's first allocations, a fixed few MiB
        Path("/proc/self/clear_refs").write_text("5")  # VmHWM := VmRSS
        before = status("VmRSS")
        model = load_model(path)
        peaks.append(round(status("VmHWM") - before, 1))
        del model
    model = load_model(path)
    print(json.dumps({"first_load_peak_mib": peaks[0], "load_peak_mib": peaks[1], "bytes_per_frame": frame_bytes(model)["per_frame"]}))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--measure", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.measure:
        measure(args.measure)
        return
    with tempfile.TemporaryDirectory() as folder:
        for name, (side, hidden) in CASES.items():
            path = Path(folder) / "model.removal"
            declared = build(path, side, hidden)
            result = subprocess.run([sys.executable, __file__, "--measure", str(path)], capture_output=True, text=True, check=True)
            measured = json.loads(result.stdout)
            print(json.dumps({"case": name, "file_mib": round(path.stat().st_size / 2**20, 2),
                              "declared_arrays_mib": round(declared / 2**20, 2), **measured,
                              "ratio": round(measured["first_load_peak_mib"] * 2**20 / declared, 2),
                              "warm_ratio": round(measured["load_peak_mib"] * 2**20 / declared, 2), "target_ratio": 4.0}), flush=True)


if __name__ == "__main__":
    main()
