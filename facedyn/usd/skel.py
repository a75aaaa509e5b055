"""UsdSkel animations baked to plain mesh points a range of frames at a time, so `import` streams a rig's performance.

Capture solvers often deliver a UsdSkel rig (a SkelRoot with a skinned Mesh, blend shapes and
a SkelAnimation of weights and joint transforms) instead of a point cache. UsdSkel's own
evaluation (UsdSkel.BakeSkinning) turns it into time-sampled points and transforms; it is
authored into the stage's session layer, in memory, so the source file is never edited.
Baking a whole take would hold every frame's points, so `plan_skel_bake` only works out which
meshes the bake animates and at which time codes (from the animation's, the skinning's and
the transforms' time samples, without baking), and `SkelBake.baked(time_codes, mesh)` bakes
one range of frames, for as long as it is read, then clears it.
"""
from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass

import numpy as np
from pxr import Gf, Usd, UsdGeom, UsdSkel

from facedyn.usd.errors import TakeError
from facedyn.usd.stage import layer_name


@dataclass
class SkelBake:
    """The SkelRoots of a stage, and the time codes their bake gives each skinned mesh's points."""

    stage: Usd.Stage
    roots: list[UsdSkel.Root]
    time_codes: dict[str, np.ndarray]  # prim path -> (F,) float64, the skinned meshes the bake animates (F > 1)
    keys: dict[str, np.ndarray]  # prim path -> the time samples that drive it (time_codes less the playback frames)

    @contextmanager
    def baked(self, time_codes: np.ndarray | None, prim: Usd.Prim) -> Iterator[None]:
        """The stage with the skinning from the first to the last of `time_codes` (None: the static value)
        baked into its session layer, cleared afterwards.

        The points UsdSkel bakes for `prim` in that range must be at the planned time codes:
        a rig this module does not foresee is an error, not frames silently missing.
        """
        path = str(prim.GetPath())
        interval = Gf.Interval() if time_codes is None else Gf.Interval(float(time_codes[0]), float(time_codes[-1]))
        try:
            _bake(self.stage, self.roots, self._reaching_keys(path, interval))
            planned = self.time_codes.get(path)
            if planned is not None and time_codes is not None:
                baked = np.array(UsdGeom.Mesh(prim).GetPointsAttr().GetTimeSamplesInInterval(interval))
                expected = planned[(planned >= interval.min) & (planned <= interval.max)]
                if not np.array_equal(baked, expected):
                    raise TakeError(f"{layer_name(self.stage)}: {path}: UsdSkel baked {len(baked)} time samples "
                                    f"in {interval.min:g}:{interval.max:g}, {len(expected)} were expected from its animation")
            yield
        finally:
            self.stage.GetSessionLayer().Clear()

    def _reaching_keys(self, path: str, interval: Gf.Interval) -> Gf.Interval:
        """`interval` widened to the driving samples of mesh `path` at or around its ends.

        UsdSkel bakes the playback frames only between the first and the last driving sample
        inside the interval it is given, so a range cut between keys needs the keys around it.
        """
        keys = self.keys.get(path)
        if keys is None or interval.IsEmpty():
            return interval
        before, after = keys[keys <= interval.min], keys[keys >= interval.max]
        return Gf.Interval(before[-1] if len(before) else interval.min, after[0] if len(after) else interval.max)


def plan_skel_bake(stage: Usd.Stage) -> SkelBake:
    """The stage's SkelRoots and, for each mesh they skin with an animation, the time codes baking would give it.

    These are the times UsdSkel.BakeSkinning samples a skeleton's meshes at: the union of its
    animation's joint and blend shape samples, its meshes' skinning and points samples and the
    transforms' samples of the skeleton and the meshes, plus the stage's playback frames
    between the first and the last of them. Nothing is baked.
    """
    roots = [UsdSkel.Root(prim) for prim in stage.Traverse() if prim.IsA(UsdSkel.Root)]
    cache = UsdSkel.Cache()
    time_codes, keys = {}, {}
    for root in roots:
        cache.Populate(root, Usd.PrimDefaultPredicate)
        for binding in cache.ComputeSkelBindings(root, Usd.PrimDefaultPredicate):
            skel_query = cache.GetSkelQuery(binding.GetSkeleton())
            skel_times = _xform_time_samples(binding.GetSkeleton().GetPrim())
            anim = skel_query.GetAnimQuery()
            if anim:
                skel_times |= set(anim.GetJointTransformTimeSamples()) | set(anim.GetBlendShapeWeightTimeSamples())
            for target in binding.GetSkinningTargets():
                prim = target.GetPrim()
                if not prim.IsA(UsdGeom.Mesh):
                    continue
                times = skel_times | _skinning_time_samples(prim) | _xform_time_samples(prim)
                if len(times) > 1:
                    keys[str(prim.GetPath())] = np.array(sorted(times))
                    time_codes[str(prim.GetPath())] = _with_playback_frames(stage, keys[str(prim.GetPath())])
    return SkelBake(stage, roots, time_codes, keys)


def _bake(stage: Usd.Stage, roots: list[UsdSkel.Root], interval: Gf.Interval) -> None:
    """Bake `roots` over `interval` into the session layer, at the stage's time codes.

    The session layer's own timeCodesPerSecond (24 unless authored) would otherwise scale
    what is baked into it on a stage at another rate (120: frame 1001 read back as 5005).
    """
    session = stage.GetSessionLayer()
    session.timeCodesPerSecond = stage.GetTimeCodesPerSecond()
    with Usd.EditContext(stage, session):
        for root in roots:
            if not UsdSkel.BakeSkinning(root, interval):
                raise TakeError(f"{layer_name(stage)}: {root.GetPath()}: UsdSkel could not bake its skinning (see USD's warnings)")


def _skinning_time_samples(prim: Usd.Prim) -> set[float]:
    """The time samples of a skinned mesh's points and its skinning (joint influences, bind transform, blend shapes).

    What UsdSkel.SkinningQuery.GetTimeSamples reads, which fails on an unauthored attribute.
    """
    binding = UsdSkel.BindingAPI(prim)
    attrs = [UsdGeom.Mesh(prim).GetPointsAttr(), binding.GetJointIndicesAttr(), binding.GetJointWeightsAttr(),
             binding.GetGeomBindTransformAttr(), binding.GetBlendShapesAttr(), binding.GetSkinningMethodAttr()]
    return {t for attr in attrs if attr for t in attr.GetTimeSamples()}


def _xform_time_samples(prim: Usd.Prim) -> set[float]:
    """The time samples of the transforms of `prim` and its ancestors (what moves it in world space)."""
    times: set[float] = set()
    while prim and not prim.IsPseudoRoot():
        if prim.IsA(UsdGeom.Xformable):
            times.update(UsdGeom.Xformable(prim).GetTimeSamples())
        prim = prim.GetParent()
    return times


def _with_playback_frames(stage: Usd.Stage, times: np.ndarray) -> np.ndarray:
    """`times` and the stage's playback frames (from its start, at its frame step) from the first to the last of them.

    As UsdSkel counts them: (end - start) / step + 1 frames truncated, and one more.
    """
    tcps, fps = stage.GetTimeCodesPerSecond(), stage.GetFramesPerSecond()
    start, end = stage.GetStartTimeCode(), stage.GetEndTimeCode()
    if not stage.HasAuthoredTimeCodeRange() or tcps == 0 or fps == 0 or end < start:
        return times
    step = abs(tcps / fps)
    playback = start + step * np.arange(int((end - start) / step + 1) + 1)
    playback = playback[(playback >= times[0]) & (playback <= times[-1])]
    return np.union1d(times, playback)
