"""UsdSkel animations baked to plain mesh caches, so `import` reads a rig's performance like any capture.

Capture solvers often deliver a UsdSkel rig (a SkelRoot with a skinned Mesh, blend shapes and
a SkelAnimation of weights and joint transforms) instead of a point cache. UsdSkel's own
evaluation (UsdSkel.BakeSkinning) turns it into time-sampled points and transforms; it is
authored into the stage's session layer, in memory, so the source file is never edited.
"""
from __future__ import annotations

from pxr import Gf, Usd, UsdSkel

from facedyn.usd.errors import TakeError
from facedyn.usd.stage import layer_name


def bake_skel_animations(stage: Usd.Stage) -> int:
    """Bake every SkelRoot of `stage` into its session layer; the number of SkelRoots baked."""
    roots = [UsdSkel.Root(prim) for prim in stage.Traverse() if prim.IsA(UsdSkel.Root)]
    with Usd.EditContext(stage, stage.GetSessionLayer()):
        for root in roots:
            if not UsdSkel.BakeSkinning(root, Gf.Interval.GetFullInterval()):
                raise TakeError(f"{layer_name(stage)}: {root.GetPath()}: UsdSkel could not bake its skinning (see USD's warnings)")
    return len(roots)
