#!/usr/bin/env python3
"""07 variant shot: switch a take between its versions in a DCC-style shot, from Python.

    python examples/07_variant_shot.py WORK_DIR

Builds WORK_DIR/shot/shot.usda whose /Shot/Actor has a "dynamics" variant set: captured,
stabilized, quasistatic and synthesized versions of the example take, each a slice of
the take's layer stack (facedyn.usd.shot.write_variant_shot). It prints one vertex's
points under each variant, then mutes the synthesized layer with Usd.Stage.MuteLayer to
show the version below it. Nothing in the take is edited. The prerequisites (corpus,
models, the take's layers) come from _setup.sh, built once.
"""
from __future__ import annotations

import hashlib
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

EXAMPLES = Path(__file__).resolve().parent


def main(argv: list[str]) -> int:
    default = os.environ.get("FACEDYN_EXAMPLE_WORK") or str(Path(tempfile.gettempdir()) / "facedyn-examples")
    work = Path(argv[1] if len(argv) > 1 and argv[1] else default).resolve()
    # The layers this example switches between: stabilized, quasistatic, synthesized.hop.
    subprocess.run(["bash", str(EXAMPLES / "_setup.sh"), str(work), "synthesized"], check=True)

    import facedyn.usd  # noqa: F401  (registers facedyn's schemas before the first stage opens)
    from pxr import Sdf, Usd, UsdGeom

    from facedyn.usd.shot import write_variant_shot

    take = work / "corpus" / os.environ.get("FACEDYN_EXAMPLE_TAKE", "smile_hop")
    capture, stabilized = take / "capture.usdc", take / "stabilized.usdc"
    quasistatic, synthesized = take / "quasistatic.usdc", take / "synthesized.hop.usdc"
    versions = {  # variant -> the take's layers, strongest first
        "captured": [capture],
        "stabilized": [stabilized, capture],
        "quasistatic": [quasistatic, stabilized, capture],
        "synthesized": [synthesized, quasistatic, stabilized, capture],
    }
    before = {p.name: hashlib.sha256(p.read_bytes()).hexdigest() for p in take.glob("*.usd*")}

    print("\n== write the shot: /Shot/Actor references the take through a 'dynamics' variant set")
    shot = work / "shot" / "shot.usda"
    shot.parent.mkdir(parents=True, exist_ok=True)
    write_variant_shot(shot, versions, prim="/Shot/Actor", variant_set="dynamics", selected="synthesized")
    print(f"wrote {shot} (+ one small root per variant beside it: {', '.join(f'{shot.stem}.{v}.usda' for v in versions)})")

    stage = Usd.Stage.Open(str(shot))
    actor = stage.GetPrimAtPath("/Shot/Actor")
    face = stage.GetPrimAtPath("/Shot/Actor/Skull/Face")
    variants = actor.GetVariantSets().GetVariantSet("dynamics")
    frame = Usd.TimeCode(round((stage.GetStartTimeCode() + stage.GetEndTimeCode()) / 2))
    # The vertex the synthesized dynamics move most at that frame.
    offsets = np.asarray(face.GetAttribute("primvars:facedyn:dynamicsOffset").Get(frame))
    vertex = int(np.argmax(np.linalg.norm(offsets, axis=1)))

    def points():
        """(skull-space points[vertex], world-space position) on the composed stage."""
        local = np.asarray(face.GetAttribute("points").Get(frame), np.float64)[vertex]
        to_world = UsdGeom.Xformable(face).ComputeLocalToWorldTransform(frame)
        return local, np.array(to_world.Transform(tuple(local)))

    fmt = lambda v: "(" + ", ".join(f"{x:9.4f}" for x in v) + ")"  # noqa: E731
    print(f"\n== vertex {vertex} at frame {int(frame.GetValue())} under each variant (cm)")
    print(f"{'variant':<13}{'points (skull space)':>36}{'world':>36}")
    seen = {}
    for name in versions:  # pipeline order (GetVariantNames() sorts them)
        variants.SetVariantSelection(name)
        local, world = seen[name] = points()
        print(f"{name:<13}{fmt(local):>36}{fmt(world):>36}")
    print("captured is in world space (skull = identity); stabilized has the same world position in skull space;")
    print("quasistatic drops the jiggle; synthesized adds new dynamics for a hop, which also moves the skull.")

    print("\n== mute synthesized.hop.usdc with Usd.Stage.MuteLayer: the quasistatic version shows through")
    variants.SetVariantSelection("synthesized")
    identifier = Sdf.Layer.FindOrOpen(str(synthesized)).identifier
    stage.MuteLayer(identifier)
    muted, _ = points()
    print(f"muted: {stage.IsLayerMuted(identifier)}; points[{vertex}] = {fmt(muted)} "
          f"(quasistatic variant: {fmt(seen['quasistatic'][0])})")
    assert np.allclose(muted, seen["quasistatic"][0], atol=1e-5), "muting the synthesized layer should show the quasistatic take"
    stage.UnmuteLayer(identifier)
    print(f"unmuted: points[{vertex}] = {fmt(points()[0])} (synthesized again)")

    after = {p.name: hashlib.sha256(p.read_bytes()).hexdigest() for p in take.glob("*.usd*")}
    assert after == before, "switching variants and muting must not edit the take's layers"
    print("\nno layer of the take was edited; open the shot in usdview and switch the variant in the Metadata tab:")
    print(f"    usdview {shot}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
