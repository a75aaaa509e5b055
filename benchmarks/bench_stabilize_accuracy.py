"""Stabilization accuracy against the simulator's truth on a rig (issue: stabilize).

Takes (120 fps, soft-tissue dynamics on, tracking noise 0.02 cm):
- dialog: Live Link speech curves under real CMU walking head motion, 651 frames;
- platform: a held smile on the 10 Hz platform;
- extreme: jaw open + funnel (about 4 cm of motion) while walking.
For every method (mode pursuit and the baselines) one JSON object: median and mean vertex
error (cm, face vertices, after one global rigid alignment), rotation (deg) and
translation (cm) errors, and the solve time. These solves are given the rig's true
neutral as the rest and its bone attachment as the mask.

``--plain`` runs the plain-capture cases instead (issue 17): takes that carry nothing but
points, with a tracker's noise (i.i.d., correlated in time and over the surface, pops,
dropped frames: facedyn.sim.noise), exported as mesh caches in metres, Z up, first frame
1001, imported and stabilized with the console defaults (benchmarks/plain_capture.py);
see plain_cases below.

    python benchmarks/bench_stabilize_accuracy.py [--rig ../shared/data/ict-facekit/ict_face_rig.usdc] [--plain [--seconds S]] [--out FILE] [--note TEXT]
"""
from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from facedyn.evaluation import stabilization_errors
from facedyn.sim.corpus import HELD_EXPRESSIONS, TakeSpec, simulate_take
from facedyn.sim.default_face import default_face
from facedyn.stabilize.api import stabilize

from harness import Recorder, parser

DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"
NOISE_CM = 0.02


def takes(rig):
    walk = f"bvh:{DATA / 'cmu-mocap' / '131_01.bvh'}" if DATA.is_dir() else "walk"
    dialog = str(DATA / "livelink-face" / "MySlate_3_Jason_Millers_iPhone.csv") if DATA.is_dir() else None
    HELD_EXPRESSIONS.setdefault("extreme", {"jawOpen": 1.0, "mouthFunnel": 1.0})
    yield TakeSpec("dialog_cmu_walk", walk, None if dialog else "smile", dialog=dialog, duration_s=651 / 120, seed=5, noise_cm=NOISE_CM)
    yield TakeSpec("smile_platform10hz", "platform:10", "smile", duration_s=3.0, seed=6, noise_cm=NOISE_CM)
    yield TakeSpec("extreme_walk", "walk", "extreme", duration_s=3.0, seed=7, noise_cm=NOISE_CM)


def main() -> None:
    arguments = parser(__doc__)
    arguments.add_argument("--rig", type=Path, help="UsdSkel blend-shape rig (default: the built-in face)")
    arguments.add_argument("--iterations", type=int, default=12)
    arguments.add_argument("--plain", action="store_true", help="the plain-capture cases (no rest, no mask) instead")
    arguments.add_argument("--seconds", type=float, help="--plain: cut every take to at most this long (default: as defined)")
    args = arguments.parse_args()
    if args.rig:
        from facedyn.usd.blendshape_rig import read_blendshape_rig

        rig = read_blendshape_rig(args.rig)
    else:
        rig = default_face()
    with Recorder("bench_stabilize_accuracy", args) as record:
        if args.plain:
            from bench_stabilize_plain import run_plain_cases

            run_plain_cases(record, rig, DATA, rig_cases=args.rig is not None, seconds=args.seconds)
        else:
            method_cases(record, rig, args.iterations)


def method_cases(record: Recorder, rig, iterations: int) -> None:
    """Every method on each take of takes(), given the rig's true neutral and bone attachment."""
    weights = rig.rigid_weights.astype(np.float64)
    three = tuple(rig.landmarks[k] for k in ("eye_corner_left", "eye_corner_right", "nose_base"))
    from facedyn.stabilize.schedule import Schedule

    for spec in takes(rig):
        take = simulate_take(rig, spec)
        world = take.world_points()
        true_skull = take.quasistatic + take.offsets
        motion = np.linalg.norm(take.quasistatic - rig.neutral, axis=-1).max()
        for method in ("mode-pursuit", "three-point", "procrustes", "icp"):
            started = time.perf_counter()
            result = stabilize(world, take.fps, method=method, rest=rig.neutral, weights=weights, three_point=three,
                               schedule=Schedule(iterations=iterations))
            seconds = time.perf_counter() - started
            errors = stabilization_errors(result.translate, result.orient, take.skull_translate, take.skull_orient,
                                          true_skull, rig.face_vertices)
            record({"case": "stabilize accuracy", "rig": rig.name, "take": spec.name, "frames": len(world),
                    "points": rig.point_count, "expression_motion_cm": round(float(motion), 2), "method": method,
                    **{k: round(v, 5) for k, v in errors.items()}, "seconds": round(seconds, 2)})


if __name__ == "__main__":
    main()
