"""`usdfacedyn validate`: USD's own validators plus facedyn's checks of a take.

facedyn's checks are the promises its layers make (DESIGN.md): offsets have one vector per
point, every frame's extent bounds its points, every layer of the stack agrees on timing,
and every frame a layer covers is authored; and the promises of a take root's stack: its
layers sit in role order, each once, each covers the take's frames and has the layer it is
computed from below it, and none is stale (computed from something no longer below it).
"""
from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from pxr import Usd, UsdGeom, UsdValidation

from facedyn.usd import schema
from facedyn.usd.errors import TakeError
from facedyn.usd.layerstack import is_take_root
from facedyn.usd.stackstatus import lists_itself, needs_message, open_root, stack_status
from facedyn.usd.stage import layer_name, open_stage, resolve_asset_path
from facedyn.usd.take import find_face_mesh, read_skull_transforms
from facedyn.usd.takechecks import frame_grid_problem, units_problem

# Validators about packaging that do not apply to plain layer files.
_SKIPPED_USD_VALIDATORS = {"usdUtilsValidators:UsdzPackageValidator", "usdUtilsValidators:PackageEncapsulationValidator"}


@dataclass
class Finding:
    severity: str  # "error" or "warning"
    validator: str
    message: str
    file: str = ""  # the layer or take the finding is about
    prim: str = ""  # the prim (or property) path, "" for the file as a whole


def validate_take(path: str | os.PathLike) -> list[Finding]:
    """Every finding about the take at `path`, each naming its file (the take when no layer is more precise).

    A root that lists itself is reported by its stack's findings alone: composing it, USD
    prints a warning of its own and goes on as if the entry were not there.
    """
    try:
        itself = lists_itself(path)
    except TakeError:
        itself = None  # an unreadable root: open_stage names it
    if itself is not None:
        return _stack_findings(Path(path))
    stage = open_stage(path)
    findings = _usd_findings(stage)
    if is_take_root(stage.GetRootLayer()):
        findings += _stack_findings(Path(path))
    findings += _timing_findings(stage)
    try:
        face = find_face_mesh(stage)
    except TakeError as exc:
        findings.append(Finding("error", "facedyn:FaceMesh", str(exc)))
    else:
        findings += _face_findings(stage, face)
    for finding in findings:
        finding.file = finding.file or layer_name(stage)
    return findings


def _usd_findings(stage: Usd.Stage) -> list[Finding]:
    registry = UsdValidation.ValidationRegistry()
    validators = [v for v in registry.GetOrLoadAllValidators() if v.GetMetadata().name not in _SKIPPED_USD_VALIDATORS]
    errors = UsdValidation.ValidationContext(validators).Validate(stage)
    findings = []
    for error in errors:
        if error.HasNoError():
            continue
        severity = "error" if error.GetType() == UsdValidation.ValidationErrorType.Error else "warning"
        site = next(iter(error.GetSites()), None)
        layer = site.GetLayer() if site is not None else None
        prim = str(site.GetPrim().GetPath()) if site is not None and site.IsPrim() else ""
        file = (layer.realPath or layer.identifier) if layer else ""
        findings.append(Finding(severity, f"usd:{error.GetName()}", error.GetMessage(), file, prim))
    return findings


def _stack_findings(root: Path) -> list[Finding]:
    """The root's layers: listed once, present, in role order, covering the take, fed by what they read, fresh."""
    findings = []
    seen = {}
    root_layer = open_root(root)
    for asset in root_layer.subLayerPaths:
        path = resolve_asset_path(asset, root.parent)
        if path == root.resolve():
            findings.append(Finding("error", "facedyn:LayerStack", f"{root}: lists itself ({asset}) among its subLayers"))
        elif path in seen:
            findings.append(Finding("error", "facedyn:LayerStack", f"{root}: lists {asset} twice (also as {seen[path]})"))
        seen.setdefault(path, asset)
    listed = [s for s in stack_status(root) if not s.muted]
    ranked = [s for s in listed if s.rank is not None]
    for upper, lower in zip(ranked, ranked[1:]):
        if upper.rank < lower.rank:
            findings.append(Finding("error", "facedyn:LayerOrder", f"{root}: {upper.asset} ({upper.role}) sits above {lower.asset} ({lower.role}), "
                                    f"whose role ranks higher; it would hide it (usdfacedyn layers can put them back in order)"))
    for s in listed:  # each layer's state as stackstatus decides it, so validate and `usdfacedyn layers` agree
        if s.state == "missing":
            findings.append(_layer_finding(s, "error", "facedyn:LayerStack", f"{root}: lists {s.asset}, which does not exist"))
        if not s.covers:
            findings.append(_layer_finding(s, "error", "facedyn:FrameCoverage", f"{s.asset}: covers frames {s.frames[0]:g}..{s.frames[1]:g}, the take "
                                    f"{s.take_frames[0]:g}..{s.take_frames[1]:g}; the frames it lacks hold its nearest value"))
        if s.needs:
            findings.append(_layer_finding(s, "error", "facedyn:LayerRequires", f"{s.asset}: {needs_message(s)}"))
        if s.stale:
            findings.append(_layer_finding(s, "warning", "facedyn:Stale", f"{s.asset}: stale, {s.reason}"))
        if s.unchecked:
            findings.append(_layer_finding(s, "warning", "facedyn:Unchecked", f"{s.asset}: {s.unchecked}"))
    return findings


def _layer_finding(status, severity: str, validator: str, message: str) -> Finding:
    return Finding(severity, validator, message, str(status.path))


def _timing_findings(stage: Usd.Stage) -> list[Finding]:
    """The take is in centimetres, Y up, and every layer that states a rate states the root's rate."""
    root = stage.GetRootLayer()
    expected = (stage.GetTimeCodesPerSecond(), stage.GetFramesPerSecond())
    findings = []
    problem = units_problem(UsdGeom.GetStageMetersPerUnit(stage), str(UsdGeom.GetStageUpAxis(stage)))
    if problem:
        findings.append(Finding("error", "facedyn:Units", problem, layer_name(stage)))
    for layer in stage.GetLayerStack(includeSessionLayers=False):
        if layer == root:
            continue
        for label, has, value, want in (
            ("timeCodesPerSecond", layer.HasTimeCodesPerSecond(), layer.timeCodesPerSecond, expected[0]),
            ("framesPerSecond", layer.HasFramesPerSecond(), layer.framesPerSecond, expected[1]),
        ):
            if has and value != want:
                findings.append(Finding("error", "facedyn:Timing", f"{layer.identifier}: {label} {value:g}, the take says {want:g}",
                                        layer.realPath or layer.identifier))
    return findings


def _face_findings(stage: Usd.Stage, face: Usd.Prim) -> list[Finding]:
    where = str(face.GetPath())
    mesh = UsdGeom.Mesh(face)
    points_attr = mesh.GetPointsAttr()
    frames = points_attr.GetTimeSamples()
    findings = []
    if not frames:
        return [Finding("error", "facedyn:Frames", f"{where}.points has no time samples", prim=where)]
    problem = frame_grid_problem(np.asarray(frames), stage.GetTimeCodesPerSecond())
    if problem:
        findings.append(Finding("error", "facedyn:Frames", f"{where}.points: {problem}", prim=where))
    counts = np.asarray(mesh.GetFaceVertexCountsAttr().Get() or [], dtype=np.int64)
    indices = np.asarray(mesh.GetFaceVertexIndicesAttr().Get() or [], dtype=np.int64)
    if counts.sum() != indices.size:
        findings.append(Finding("error", "facedyn:Topology", f"{where}: faceVertexCounts sum {counts.sum()} != {indices.size} indices"))
    offsets_attr = face.GetAttribute(schema.OFFSETS_ATTR)
    has_offsets = bool(offsets_attr and offsets_attr.HasAuthoredValue())
    if has_offsets:
        interpolation = UsdGeom.Primvar(offsets_attr).GetInterpolation()
        if interpolation != UsdGeom.Tokens.vertex:
            findings.append(Finding("error", "facedyn:Offsets", f"{where}: dynamicsOffset interpolation is {interpolation}, expected vertex"))
        missing = sorted(set(frames) - set(offsets_attr.GetTimeSamples()))
        if missing:
            findings.append(Finding("error", "facedyn:Offsets", f"{where}: no dynamicsOffset at {len(missing)} frame(s), first {missing[0]:g}"))
    extent_attr = mesh.GetExtentAttr()
    points_q, extent_q = Usd.AttributeQuery(points_attr), Usd.AttributeQuery(extent_attr)
    offsets_q = Usd.AttributeQuery(offsets_attr) if has_offsets else None
    bad_extent = bad_offsets = bad_points = None
    for t in frames:
        points = np.asarray(points_q.Get(t), dtype=np.float64)
        if bad_points is None and (points.size == 0 or not np.isfinite(points).all() or indices.size and indices.max() >= len(points)):
            bad_points = t
        extent = extent_q.Get(t)
        if bad_extent is None and points.size and (
            extent is None or not np.allclose(np.asarray(extent), [points.min(0), points.max(0)], atol=1e-4, rtol=1e-5)
        ):
            bad_extent = t
        if offsets_q is not None and bad_offsets is None:
            offsets = offsets_q.Get(t)
            if offsets is not None and len(offsets) != len(points):
                bad_offsets = (t, len(offsets), len(points))
    if bad_points is not None:
        findings.append(Finding("error", "facedyn:Points", f"{where}: points at time {bad_points:g} are empty, non-finite or fewer than the topology indexes"))
    if bad_extent is not None:
        findings.append(Finding("error", "facedyn:Extent", f"{where}: extent at time {bad_extent:g} does not bound that frame's points"))
    if bad_offsets is not None:
        t, n_off, n_pts = bad_offsets
        findings.append(Finding("error", "facedyn:Offsets", f"{where}: {n_off} dynamicsOffset values for {n_pts} points at time {t:g}"))
    for finding in findings:
        finding.prim = finding.prim or where
    findings += _skull_findings(face.GetParent(), frames)
    return findings


def _skull_findings(skull: Usd.Prim, frames: list[float]) -> list[Finding]:
    """The skull's transform reads as the readers read it: a value at every frame of the face, unit quaternions."""
    if not skull.HasAPI(schema.SKULL_API):
        return []
    findings = []
    try:
        read_skull_transforms(skull, np.asarray(frames, dtype=np.float64))
    except TakeError as exc:
        findings.append(Finding("error", "facedyn:Skull", str(exc), prim=str(skull.GetPath())))
    order = UsdGeom.Xformable(skull).GetXformOpOrderAttr().Get()
    if order is not None and [str(o) for o in order] != ["xformOp:translate", "xformOp:orient"]:
        findings.append(Finding("warning", "facedyn:Skull", f"{skull.GetPath()}: xformOpOrder {list(order)} is not [translate, orient]",
                                prim=str(skull.GetPath())))
    return findings
