"""`usdfacedyn import` of a UsdSkel rig in bounded memory: peak RSS and speed on long takes.

The source is the built-in 4,058-point face (facedyn.sim.default_face) written as a
blend-shape rig (facedyn.usd.blendshape_rig.write_blendshape_rig: a SkelRoot, the Face mesh, 32 blend
shapes), and a performance layer over it (sublayered, as a capture solver delivers it): a
Skeleton of one joint bound to the face and a SkelAnimation keying every frame the 27
expression weights and the joint's translation and rotation (the head moving), saved chunk
by chunk so the writer never holds the take. Then `usdfacedyn import` runs in its own process
(bench_long_take.run_step): its peak RSS is the process's VmHWM; throughput is frames per
second of its wall time.

    python benchmarks/bench_import_skel.py [--frames 2000 10000] [--workdir DIR] [--keep] [--out FILE] [--note TEXT]

Prints one JSON object per --frames count. Disk: about 0.05 MB per frame for the capture
layer, a few hundred bytes per frame for the animation; removed afterwards unless --keep.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from bench_import import CHUNK, built_in_face, import_case
from harness import Recorder, parser
from spill import work_folder, work_folder_arguments

RIG_FPS = 24.0  # USD's default rate: the rig layer is sublayered unscaled (and imports before this streamed could read it)


def write_skel_take(folder: Path, count: int) -> Path:
    """performance.usdc (over rig.usdc): `count` frames of expression weights and head motion from frame 1001."""
    from pxr import Gf, Sdf, Usd, UsdSkel, Vt

    from facedyn.usd.blendshape_rig import write_blendshape_rig

    face = built_in_face()
    rig = write_blendshape_rig(face, folder / "rig.usdc")
    layer = Sdf.Layer.CreateNew(str(folder / f"performance_{count}.usdc"))
    layer.subLayerPaths = [str(rig)]
    stage = Usd.Stage.Open(layer)
    stage.SetTimeCodesPerSecond(RIG_FPS)
    stage.SetFramesPerSecond(RIG_FPS)
    layer.defaultPrim = Sdf.Layer.FindOrOpen(str(rig)).defaultPrim
    root = stage.GetDefaultPrim().GetPath()
    skel = UsdSkel.Skeleton.Define(stage, root.AppendChild("Skel"))
    skel.CreateJointsAttr(["head"])
    skel.CreateBindTransformsAttr([Gf.Matrix4d(1)])
    skel.CreateRestTransformsAttr([Gf.Matrix4d(1)])
    anim = UsdSkel.Animation.Define(stage, skel.GetPath().AppendChild("Anim"))
    anim.CreateJointsAttr(["head"])
    anim.CreateBlendShapesAttr(list(face.expression_names))
    anim.CreateScalesAttr().Set(Vt.Vec3hArray([Gf.Vec3h(1, 1, 1)]))
    UsdSkel.BindingAPI.Apply(skel.GetPrim()).CreateAnimationSourceRel().SetTargets([anim.GetPath()])
    binding = UsdSkel.BindingAPI.Apply(stage.GetPrimAtPath(root.AppendChild("Face")))
    binding.CreateSkeletonRel().SetTargets([skel.GetPath()])
    binding.CreateJointIndicesPrimvar(constant=True, elementSize=1).Set([0])
    binding.CreateJointWeightsPrimvar(constant=True, elementSize=1).Set([1.0])
    weights, translations, rotations = (attr.GetPath() for attr in (
        anim.CreateBlendShapeWeightsAttr(), anim.CreateTranslationsAttr(), anim.CreateRotationsAttr()))
    layer.Save()
    phases = np.arange(face.expression_count) * 0.37
    for a in range(0, count, CHUNK):
        t = np.arange(a, min(count, a + CHUNK)) / RIG_FPS
        with Sdf.ChangeBlock():
            for k, s in enumerate(t):
                frame = 1001.0 + a + k
                layer.SetTimeSample(weights, frame, Vt.FloatArray.FromNumpy(
                    (0.5 + 0.5 * np.sin(1.3 * s + phases)).astype(np.float32)))
                layer.SetTimeSample(translations, frame, Vt.Vec3fArray([Gf.Vec3f(np.sin(0.7 * s), 0.3 * np.sin(1.3 * s), 0)]))
                layer.SetTimeSample(rotations, frame, Vt.QuatfArray([Gf.Quatf(Gf.Rotation(Gf.Vec3d(0, 1, 0), 10 * np.sin(0.5 * s)).GetQuat())]))
        layer.Save()
    return Path(layer.realPath)


def main() -> None:
    arguments = parser(__doc__)
    arguments.add_argument("--frames", type=int, nargs="+", default=[2_000, 10_000])
    work_folder_arguments(arguments)
    args = arguments.parse_args()
    with work_folder("bench_import_skel.", args) as work, Recorder("bench_import_skel", args) as record:
        for frames in args.frames:
            source = write_skel_take(work, frames)
            record(import_case(f"skel {frames}", source, work, frames))


if __name__ == "__main__":
    main()
