"""Ground-truth corpus on a rig: offset magnitudes per motion and simulation speed.

Simulates one take per motion of the protocol (held smile; platform 6..11 Hz; dialog under
real CMU walking and hopping when ../shared/data is there) and prints one JSON object per
take: peak and RMS offsets over the face (mm) and simulated frames per second; then one
object for writing a take to USD and one with the path of a rendered offset picture (both
in --folder).

    python benchmarks/bench_corpus.py [--rig ../shared/data/ict-facekit/ict_face_rig.usdc] [--folder DIR] [--out FILE] [--note TEXT]
"""
from __future__ import annotations

import os
import tempfile
import time
from pathlib import Path

import numpy as np

from facedyn.sim.corpus import MOTIONS, TakeSpec, dialog_takes, simulate_take, simulate_takes
from facedyn.sim.default_face import default_face

from harness import Recorder, parser

DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"


def main() -> None:
    arguments = parser(__doc__)
    arguments.add_argument("--rig", type=Path, help="UsdSkel blend-shape rig (default: the built-in face)")
    arguments.add_argument("--seconds", type=float, default=3.0)
    arguments.add_argument("--folder", type=Path, default=Path(tempfile.gettempdir()) / "facedyn-bench-corpus",
                           help="where the loudest take and its offset picture are written")
    args = arguments.parse_args()
    with Recorder("bench_corpus", args) as record:
        measure(record, args)


def measure(record: Recorder, args) -> None:
    """Each take simulated alone, the corpus on every core, then the loudest take written and pictured."""
    if args.rig:
        from facedyn.usd.blendshape_rig import read_blendshape_rig

        rig = read_blendshape_rig(args.rig)
    else:
        rig = default_face()
    specs = [TakeSpec(f"smile_{m.replace(':', '')}", m, "smile", duration_s=args.seconds, seed=i) for i, m in enumerate(MOTIONS)]
    specs += dialog_takes(DATA if DATA.is_dir() else None, 6.0, 1000, 0.0)
    face = rig.face_vertices
    total_frames = total_seconds = 0.0
    loudest = None
    for spec in specs:
        started = time.perf_counter()
        take = simulate_take(rig, spec)
        seconds = time.perf_counter() - started
        magnitude = np.linalg.norm(take.offsets[:, face], axis=-1) * 10
        total_frames += len(take.frames)
        total_seconds += seconds
        if loudest is None or magnitude.max() > loudest[0]:
            loudest = (float(magnitude.max()), take)
        record({"case": "simulate", "rig": rig.name, "points": rig.point_count, "take": spec.name, "motion": spec.motion,
                "frames": len(take.frames), "peak_offset_mm": round(float(magnitude.max()), 2),
                "rms_offset_mm": round(float(np.sqrt(np.mean(magnitude**2))), 2),
                "frames_per_s": round(len(take.frames) / seconds, 1)})
    record({"case": "simulate (one take at a time)", "rig": rig.name, "points": rig.point_count, "frames": int(total_frames),
            "frames_per_s": round(total_frames / total_seconds, 1)})
    jobs = os.cpu_count() or 1
    started = time.perf_counter()
    frames = sum(len(take.frames) for take in simulate_takes(rig, specs, jobs=jobs))
    record({"case": "build corpus (takes on every core)", "rig": rig.name, "points": rig.point_count, "jobs": jobs,
            "frames": frames, "frames_per_s": round(frames / (time.perf_counter() - started), 1),
            "target_frames_per_s": 200})
    write_and_render(record, rig, loudest[1], args.folder)


def write_and_render(record: Recorder, rig, take, out: Path) -> None:
    from facedyn.preview.images import write_image
    from facedyn.preview.review import review_sheet
    from facedyn.usd.corpus_files import write_simulated_take

    out.mkdir(parents=True, exist_ok=True)
    started = time.perf_counter()
    write_simulated_take(out / take.spec.name, take, rig)
    seconds = time.perf_counter() - started
    record({"case": "write take (capture + truth layers)", "frames": len(take.frames), "seconds": round(seconds, 2),
            "frames_per_s": round(len(take.frames) / seconds, 1)})
    peak = int(np.argmax(np.linalg.norm(take.offsets, axis=-1).max(axis=1)))
    sheet, range_mm = review_sheet([(f"{take.spec.name}: true offsets", take.quasistatic + take.offsets, take.offsets)],
                                   rig.topology.triangles(), take.frames, [max(peak - 6, 0), peak, min(peak + 6, len(take.frames) - 1)], size=384)
    path = write_image(out / f"{take.spec.name}_offsets.png", sheet)
    record({"case": "offset picture", "path": str(path), "range_mm": range_mm, "frame": float(take.frames[peak])})


if __name__ == "__main__":
    main()
