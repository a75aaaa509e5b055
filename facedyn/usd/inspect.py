"""`usdfacedyn inspect`: what a take is made of, strongest layer first, with each layer's role and staleness."""
from __future__ import annotations

import json
import os
from pathlib import Path

from pxr import Sdf, UsdGeom

from facedyn.usd import schema
from facedyn.usd.layerstack import is_take_root, layer_metadata, recorded_role_name
from facedyn.usd.stackstatus import LayerStatus, stack_status
from facedyn.usd.stage import open_stage
from facedyn.usd.take import find_face_mesh


def describe_take(path: str | os.PathLike) -> dict:
    """The layer stack (with each layer's role and provenance), timing and the face's summary."""
    stage = open_stage(path)
    description: dict = {
        "take": str(path),
        "timing": {
            "timeCodesPerSecond": stage.GetTimeCodesPerSecond(),
            "framesPerSecond": stage.GetFramesPerSecond(),
            "startTimeCode": stage.GetStartTimeCode(),
            "endTimeCode": stage.GetEndTimeCode(),
            "metersPerUnit": UsdGeom.GetStageMetersPerUnit(stage),
            "upAxis": str(UsdGeom.GetStageUpAxis(stage)),
        },
    }
    statuses = stack_status(path) if is_take_root(stage.GetRootLayer()) else []
    by_path = {s.path: s for s in statuses}
    description["layers"] = [
        _describe_layer(layer, by_path.get(Path(layer.realPath).resolve()) if layer.realPath else None)
        for layer in stage.GetLayerStack(includeSessionLayers=False)
    ]
    description["mutedOnDisk"] = [s.asset for s in statuses if s.muted]
    face = find_face_mesh(stage)
    mesh = UsdGeom.Mesh(face)
    points_attr = mesh.GetPointsAttr()
    samples = points_attr.GetTimeSamples()
    first = points_attr.Get(samples[0]) if samples else points_attr.Get()
    skull = face.GetParent()
    description["face"] = {
        "prim": str(face.GetPath()),
        "role": schema.FaceAttributes.read(face).role,
        "points": len(first) if first is not None else 0,
        "faces": len(mesh.GetFaceVertexCountsAttr().Get() or []),
        "frames": len(samples),
        "frameRange": [samples[0], samples[-1]] if samples else None,
        "hasDynamicsOffsets": bool(face.GetAttribute(schema.OFFSETS_ATTR).HasAuthoredValue()),
        "skull": str(skull.GetPath()) if skull.HasAPI(schema.SKULL_API) else None,
        "skullSolver": schema.SkullAttributes.read(skull).solver if skull.HasAPI(schema.SKULL_API) else None,
        "provenance": schema.read_provenance(face),
    }
    return description


def _describe_layer(layer: Sdf.Layer, status: LayerStatus | None) -> dict:
    data = layer_metadata(layer) or {}
    entry = {
        "layer": layer.realPath or layer.identifier,
        "processor": data.get("processor", data.get("role", "")),
        "version": data.get("version", ""),
        "frameRange": list(data["frameRange"]) if "frameRange" in data else None,
        "inputs": list(data.get("inputs", [])),
        "parameters": json.loads(data["parameters"]) if "parameters" in data else {},
        "role": recorded_role_name(data) or "",
        "run": data.get("run", ""),
        "stale": bool(status and status.stale),
        "staleReason": status.reason if status else "",
        "coversTake": status.covers if status else True,
    }
    return entry


def format_description(d: dict) -> str:
    t = d["timing"]
    face = d["face"]
    lines = [
        f"take: {d['take']}",
        f"timing: {t['timeCodesPerSecond']:g} time codes/s, {t['framesPerSecond']:g} fps, "
        f"{t['startTimeCode']:g}..{t['endTimeCode']:g}, metersPerUnit {t['metersPerUnit']:g}, up {t['upAxis']}",
        f"face: {face['prim']} ({face['points']} points, {face['faces']} faces, {face['frames']} frames), "
        f"role {face['role']}, skull solver {face['skullSolver']}, offsets {'yes' if face['hasDynamicsOffsets'] else 'no'}",
        "layer stack (strongest first):",
    ]
    for i, layer in enumerate(d["layers"]):
        name = Path(layer["layer"]).name if not layer["layer"].startswith("anon:") else layer["layer"]
        what = layer["processor"] or "-"
        detail = f"role {layer['role']}" if layer["role"] else ""
        if layer["frameRange"]:
            detail += f", frames {layer['frameRange'][0]:g}..{layer['frameRange'][1]:g}"
        if layer["version"]:
            detail += f", {layer['version']}"
        if not layer["coversTake"]:
            detail += " (fewer frames than the take)"
        lines.append(f"  {i}. {name:<32} {what:<12} {detail.lstrip(', ')}")
        if layer["stale"]:
            lines.append(f"       STALE: {layer['staleReason']}")
        if layer["parameters"]:
            lines.append(f"       parameters: {json.dumps(layer['parameters'], sort_keys=True)}")
    lines += [f"  muted on disk: {asset}" for asset in d.get("mutedOnDisk", [])]
    return "\n".join(lines)
