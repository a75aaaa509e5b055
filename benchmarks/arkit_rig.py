"""An ARKit-named blend-shape rig of about 2.7k points, built from the shared ICT-FaceKit rig:
a rig neither the built-in face nor ICT as shipped, the size of issue 37's evaluation rig.

ICT's mesh is decimated (quadric decimation, fast-simplification) to about TARGET points,
each kept vertex an ICT vertex (the nearest to the decimated one), so its shapes, identity
modes, rigid and face regions and landmarks are ICT's, subset; the shapes are named as
ARKit names them (eyeBlink_L -> eyeBlinkLeft; browInnerUp_L + _R -> browInnerUp and
cheekPuff_L + _R -> cheekPuff, which ARKit does not split). Deterministic: the same ICT file
gives the same rig.

    python benchmarks/arkit_rig.py -o /tmp/bench/arkit_rig.usdc [--points 2700] [--ict ../shared/data/ict-facekit/ict_face_rig.usdc]
"""
from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from facedyn.performance import Topology
from facedyn.rig import FaceRig

ICT = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "ict-facekit" / "ict_face_rig.usdc"
TARGET = 2700
MERGED = ("browInnerUp", "cheekPuff")  # shapes ARKit has once for both sides


def arkit_name(name: str) -> str:
    """ICT's side suffix as ARKit spells it: eyeBlink_L -> eyeBlinkLeft."""
    return name[:-2] + ("Left" if name.endswith("_L") else "Right") if name.endswith(("_L", "_R")) else name


def decimated(points: np.ndarray, triangles: np.ndarray, target: int) -> tuple[np.ndarray, np.ndarray]:
    """(the kept original vertices, triangles over them) of a mesh decimated to about `target` points."""
    import fast_simplification
    from scipy.spatial import cKDTree

    used = np.unique(triangles)
    simple, faces = fast_simplification.simplify(points.astype(np.float64), triangles, target_count=2 * target)
    _, nearest = cKDTree(points[used]).query(simple)
    keep, inverse = np.unique(used[nearest], return_inverse=True)
    faces = inverse[faces]
    faces = faces[(faces[:, 0] != faces[:, 1]) & (faces[:, 1] != faces[:, 2]) & (faces[:, 0] != faces[:, 2])]
    _, first = np.unique(np.sort(faces, axis=1), axis=0, return_index=True)
    faces = faces[np.sort(first)]
    referenced = np.unique(faces)  # a vertex no triangle kept is dropped
    renumber = -np.ones(len(keep), np.int64)
    renumber[referenced] = np.arange(len(referenced))
    return keep[referenced], renumber[faces]


def arkit_rig(ict_path: Path = ICT, target: int = TARGET) -> FaceRig:
    """The ARKit-named rig decimated from the ICT rig at `ict_path` (see the module's docstring)."""
    from scipy.spatial import cKDTree

    from facedyn.usd.blendshape_rig import read_blendshape_rig

    ict = read_blendshape_rig(ict_path)
    keep, faces = decimated(ict.neutral, ict.topology.triangles(), target)
    index = -np.ones(ict.point_count, np.int64)
    index[keep] = np.arange(len(keep))
    names: list[str] = []
    shapes: list[np.ndarray] = []
    for name in ict.expression_names:
        dense = ict.dense_offsets(name)[keep]
        base = name[:-2] if name.endswith(("_L", "_R")) else name
        if base in MERGED and base in names:
            shapes[names.index(base)] = shapes[names.index(base)] + dense
            continue
        names.append(base if base in MERGED else arkit_name(name))
        shapes.append(dense.copy())

    def subset(vertices) -> np.ndarray:
        kept = index[np.asarray(vertices)]
        return kept[kept >= 0]

    nearest = cKDTree(ict.neutral[keep])
    return FaceRig(name="arkit_face", neutral=ict.neutral[keep],
                   topology=Topology(np.full(len(faces), 3, np.int32), faces.ravel().astype(np.int32)),
                   expression_names=tuple(names), expression_offsets=np.stack(shapes), identity_modes=ict.identity_modes[:, keep],
                   face_vertices=subset(ict.face_vertices), rigid_vertices=subset(ict.rigid_vertices),
                   landmarks={key: int(nearest.query(ict.neutral[v])[1]) for key, v in ict.landmarks.items()})


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.strip().splitlines()[0])
    parser.add_argument("-o", "--output", type=Path, required=True, help="the rig file to write (.usdc or .usda)")
    parser.add_argument("--points", type=int, default=TARGET, help="about how many points")
    parser.add_argument("--ict", type=Path, default=ICT, help="the ICT-FaceKit rig")
    args = parser.parse_args()
    from facedyn.usd.blendshape_rig import write_blendshape_rig

    rig = arkit_rig(args.ict, args.points)
    args.output.parent.mkdir(parents=True, exist_ok=True)
    write_blendshape_rig(rig, args.output)
    print(f"{args.output}: {rig.point_count} points, {len(rig.topology.face_vertex_counts)} triangles, {rig.expression_count} shapes")


if __name__ == "__main__":
    main()
