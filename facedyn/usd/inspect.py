"""`usdfacedyn inspect`: what a take is made of, strongest layer first, with each layer's role and staleness.

Provenance metadata is shown as recorded; a field of the wrong type or unparseable JSON is
listed among the layer's `problems` instead of stopping the report. A single result layer
(which overrides a face some other layer defines) is described by its provenance: role,
processor, run and inputs, and which take root to inspect for the composed take.
"""
from __future__ import annotations

import json
import os
from pathlib import Path

from pxr import Sdf, UsdGeom

from facedyn.usd import schema
from facedyn.usd.errors import TakeError
from facedyn.usd.layerstack import is_take_root, layer_metadata, recorded_role_name
from facedyn.usd.stackstatus import LayerStatus, frame_range, needs_message, stack_status
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
    try:
        face = find_face_mesh(stage)
    except TakeError:
        if statuses or not layer_metadata(stage.GetRootLayer()):
            raise
        description["face"] = None  # a result layer on its own: its provenance says what it is
        return description
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
    problems = [f"{key} is a {type(data[key]).__name__}, expected text" for key in ("processor", "version", "role", "run")
                if key in data and not isinstance(data[key], str)]
    text = {key: value for key, value in data.items() if isinstance(value, str)}
    frames = frame_range(data)
    if "frameRange" in data and frames is None:
        problems.append("frameRange is not two finite frame numbers")
    inputs = schema.string_list(data.get("inputs", []))
    if inputs is None:
        problems.append(f"inputs is a {type(data['inputs']).__name__}, expected a list of layers")
    parameters, problem = _parameters(data)
    entry = {
        "layer": layer.realPath or layer.identifier,
        "processor": text.get("processor", text.get("role", "")),
        "version": text.get("version", ""),
        "frameRange": list(frames) if frames else None,
        "inputs": inputs or [],
        "parameters": parameters,
        "role": (recorded_role_name(text) or "") if "role" in text or "processor" in text else "",
        "run": text.get("run", ""),
        "stale": bool(status and status.state == "stale"),
        "staleReason": (status.reason or (needs_message(status) if status.needs else "")) if status else "",
        "unchecked": status.unchecked if status else "",
        "coversTake": status.covers if status else True,
        "problems": problems + ([problem] if problem else []),
    }
    return entry


def _parameters(data: dict) -> tuple[dict, str]:
    """The recorded parameters (a JSON object in text) and what is wrong with them ("" when nothing)."""
    raw = data.get("parameters", "{}")
    if not isinstance(raw, str):
        return {}, f"parameters is a {type(raw).__name__}, expected JSON text"
    try:
        parameters = json.loads(raw)
    except ValueError as exc:
        return {}, f"parameters are not valid JSON ({exc})"
    if not isinstance(parameters, dict):
        return {}, f"parameters are JSON {type(parameters).__name__}, expected an object"
    return parameters, ""


def format_description(d: dict) -> str:
    t = d["timing"]
    face = d["face"]
    timing = (f"timing: {t['timeCodesPerSecond']:g} time codes/s, {t['framesPerSecond']:g} fps, "
              f"{t['startTimeCode']:g}..{t['endTimeCode']:g}, metersPerUnit {t['metersPerUnit']:g}, up {t['upAxis']}")
    if face is None:
        return _format_result_layer(d["take"], d["layers"][0], timing)
    lines = [
        f"take: {d['take']}",
        timing,
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
        if layer["unchecked"]:
            lines.append(f"       unchecked: {layer['unchecked']}")
        if layer["parameters"]:
            lines.append(f"       parameters: {json.dumps(layer['parameters'], sort_keys=True)}")
        lines += [f"       malformed provenance: {problem}" for problem in layer["problems"]]
    lines += [f"  muted on disk: {asset}" for asset in d.get("mutedOnDisk", [])]
    return "\n".join(lines)


def _format_result_layer(path: str, layer: dict, timing: str) -> str:
    """A result layer inspected on its own: what wrote it, from what, and where to look for the take."""
    frames = f", frames {layer['frameRange'][0]:g}..{layer['frameRange'][1]:g}" if layer["frameRange"] else ""
    lines = [
        f"layer: {path}",
        f"a {layer['role'] or 'facedyn'} layer written by {layer['processor'] or 'an unknown processor'}"
        f"{' ' + layer['version'] if layer['version'] else ''} (run {layer['run'] or '-'}){frames}",
        timing,
        f"inputs: {', '.join(layer['inputs']) or '-'}",
    ]
    if layer["parameters"]:
        lines.append(f"parameters: {json.dumps(layer['parameters'], sort_keys=True)}")
    lines += [f"malformed provenance: {problem}" for problem in layer["problems"]]
    lines.append("it overrides a face defined in another layer: inspect the take root that lists it (e.g. take.usda) for the composed take")
    return "\n".join(lines)
