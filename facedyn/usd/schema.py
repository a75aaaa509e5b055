"""Thin Python wrappers over facedyn's codeless API schemas.

The schemas have no generated C++ classes (they are codeless), so these helpers name their
properties once and read/write them as NumPy arrays.
"""
from __future__ import annotations

import json
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from pxr import Sdf, Usd, Vt

from facedyn.performance import CAPTURED
from facedyn.usd.runs import INPUT_IDENTITY, LayerInput, run_id
from facedyn.usd.stage import relative_asset_path

SKULL_API = "FacedynSkullAPI"
FACE_API = "FacedynFaceAPI"
PROCESSOR_API = "FacedynProcessorAPI"

LANDMARKS_ATTR = "facedyn:skull:landmarks"
SOLVER_ATTR = "facedyn:skull:solver"
SOLVE_ERROR_ATTR = "facedyn:skull:solveError"
REFERENCE_FRAME_ATTR = "facedyn:skull:referenceFrame"

ROLE_ATTR = "facedyn:face:role"
REST_POINTS_ATTR = "facedyn:face:restPoints"
SKIN_SAMPLES_ATTR = "facedyn:face:skinSamples"
RIGID_WEIGHTS_ATTR = "facedyn:face:rigidWeights"
FACE_VERTICES_ATTR = "facedyn:face:faceVertices"
ALIGNMENT_VERTICES_ATTR = "facedyn:face:alignmentVertices"
OFFSETS_ATTR = "primvars:facedyn:dynamicsOffset"


def _get(prim: Usd.Prim, name: str, dtype) -> np.ndarray | None:
    attr = prim.GetAttribute(name)
    if not attr or not attr.HasAuthoredValue():
        return None
    value = attr.Get()
    return None if value is None else np.asarray(value, dtype=dtype)


@dataclass
class FaceAttributes:
    """The static FacedynFaceAPI values of a face mesh."""

    role: str | None = CAPTURED  # None: this layer says nothing about the role
    rest_points: np.ndarray | None = None
    skin_samples: np.ndarray | None = None
    rigid_weights: np.ndarray | None = None
    face_vertices: np.ndarray | None = None
    alignment_vertices: np.ndarray | None = None  # (3,) eye corners L/R, under the nose

    @classmethod
    def read(cls, prim: Usd.Prim) -> "FaceAttributes":
        role = prim.GetAttribute(ROLE_ATTR).Get() if prim.HasAPI(FACE_API) else None
        return cls(
            role=str(role) if role else CAPTURED,
            rest_points=_get(prim, REST_POINTS_ATTR, np.float32),
            skin_samples=_get(prim, SKIN_SAMPLES_ATTR, np.int32),
            rigid_weights=_get(prim, RIGID_WEIGHTS_ATTR, np.float32),
            face_vertices=_get(prim, FACE_VERTICES_ATTR, np.int32),
            alignment_vertices=_get(prim, ALIGNMENT_VERTICES_ATTR, np.int32),
        )

    def write(self, prim: Usd.Prim) -> None:
        prim.ApplyAPI(FACE_API)
        if self.role is not None:
            prim.CreateAttribute(ROLE_ATTR, Sdf.ValueTypeNames.Token).Set(self.role)
        arrays = (
            (REST_POINTS_ATTR, Sdf.ValueTypeNames.Point3fArray, Vt.Vec3fArray, self.rest_points, np.float32),
            (SKIN_SAMPLES_ATTR, Sdf.ValueTypeNames.IntArray, Vt.IntArray, self.skin_samples, np.int32),
            (RIGID_WEIGHTS_ATTR, Sdf.ValueTypeNames.FloatArray, Vt.FloatArray, self.rigid_weights, np.float32),
            (FACE_VERTICES_ATTR, Sdf.ValueTypeNames.IntArray, Vt.IntArray, self.face_vertices, np.int32),
            (ALIGNMENT_VERTICES_ATTR, Sdf.ValueTypeNames.IntArray, Vt.IntArray, self.alignment_vertices, np.int32),
        )
        for name, type_name, vt_type, value, dtype in arrays:
            if value is not None:
                prim.CreateAttribute(name, type_name).Set(vt_type.FromNumpy(np.ascontiguousarray(value, dtype=dtype)))


@dataclass
class SkullAttributes:
    """The static FacedynSkullAPI values of a skull Xform."""

    solver: str = "identity"
    landmarks: np.ndarray | None = None
    reference_frame: float | None = None

    @classmethod
    def read(cls, prim: Usd.Prim) -> "SkullAttributes":
        solver = prim.GetAttribute(SOLVER_ATTR).Get() if prim.HasAPI(SKULL_API) else None
        reference = prim.GetAttribute(REFERENCE_FRAME_ATTR)
        return cls(
            solver=str(solver) if solver else "identity",
            landmarks=_get(prim, LANDMARKS_ATTR, np.float32),
            reference_frame=reference.Get() if reference and reference.HasAuthoredValue() else None,
        )

    def write(self, prim: Usd.Prim) -> None:
        prim.ApplyAPI(SKULL_API)
        prim.CreateAttribute(SOLVER_ATTR, Sdf.ValueTypeNames.Token).Set(self.solver)
        if self.landmarks is not None:
            value = Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(self.landmarks, dtype=np.float32))
            prim.CreateAttribute(LANDMARKS_ATTR, Sdf.ValueTypeNames.Point3fArray).Set(value)
        if self.reference_frame is not None:
            prim.CreateAttribute(REFERENCE_FRAME_ATTR, Sdf.ValueTypeNames.Double).Set(float(self.reference_frame))


@dataclass
class Provenance:
    """One processor run as its caller describes it (inputs as paths, labels or read LayerInputs).

    `record` turns it into the `RunRecord` a layer stores: inputs relative to the layer and
    identified by their runs, and the run's own deterministic id.
    """

    processor: str
    version: str
    parameters: dict
    frame_range: tuple[float, float]
    inputs: list[str | os.PathLike | LayerInput]
    role: str | None = None  # a performance.Role name; None: the writer decides (write_layer)

    def record(self, anchor_dir: Path, role: str) -> "RunRecord":
        """This run as stored in a layer written into anchor_dir, with role `role`."""
        inputs = [LayerInput.of(i) for i in self.inputs]
        parameters = json.dumps(self.parameters, sort_keys=True, default=str)
        frame_range = (float(self.frame_range[0]), float(self.frame_range[-1]))
        return RunRecord(
            processor=self.processor,
            role=role,
            version=self.version,
            parameters=parameters,
            frame_range=frame_range,
            inputs=tuple(relative_asset_path(i.path, anchor_dir) if os.path.isabs(i.path) else i.path for i in inputs),
            input_runs=tuple(i.run for i in inputs),
            input_kinds=tuple(i.kind for i in inputs),
            run=run_id(self.processor, self.version, parameters, frame_range, [i.run for i in inputs]),
        )


@dataclass(frozen=True)
class RunRecord:
    """One processor run as a layer records it: in customLayerData and as a FacedynProcessorAPI instance."""

    processor: str
    role: str
    version: str
    parameters: str  # JSON, keys sorted
    frame_range: tuple[float, float]
    inputs: tuple[str, ...]  # asset paths relative to the layer (or labels that name no file)
    input_runs: tuple[str, ...]  # each input's content id (runs.content_id; "" for a label)
    input_kinds: tuple[str, ...]  # each input's kind: runs.LAYER (of the stack read) or runs.FILE
    run: str

    @property
    def instance_name(self) -> str:
        return self.processor.replace("-", "_")

    def as_dict(self) -> dict:
        """The run as layer metadata (customLayerData["facedyn"]); arrays as typed Vt arrays."""
        return {
            "processor": self.processor,
            "role": self.role,
            "version": self.version,
            "parameters": self.parameters,
            "frameRange": Vt.DoubleArray(list(self.frame_range)),
            "inputs": Vt.StringArray(list(self.inputs)),
            "inputRuns": Vt.StringArray(list(self.input_runs)),
            "inputKinds": Vt.StringArray(list(self.input_kinds)),
            "inputIdentity": INPUT_IDENTITY,
            "run": self.run,
        }

    def write(self, prim: Usd.Prim) -> None:
        prim.ApplyAPI(PROCESSOR_API, self.instance_name)
        prefix = f"facedyn:processor:{self.instance_name}:"
        types = Sdf.ValueTypeNames
        prim.CreateAttribute(prefix + "processor", types.Token).Set(self.processor)
        prim.CreateAttribute(prefix + "role", types.Token).Set(self.role)
        prim.CreateAttribute(prefix + "version", types.String).Set(self.version)
        prim.CreateAttribute(prefix + "parameters", types.String).Set(self.parameters)
        prim.CreateAttribute(prefix + "frameRange", types.Double2).Set(self.frame_range)
        prim.CreateAttribute(prefix + "inputs", types.StringArray).Set(list(self.inputs))
        prim.CreateAttribute(prefix + "inputRuns", types.StringArray).Set(list(self.input_runs))
        prim.CreateAttribute(prefix + "run", types.String).Set(self.run)


def recorded_inputs(data: dict) -> list[dict]:
    """customLayerData["facedyn"]'s inputs as [{layer, run, kind}] (run "" where an older layer kept none; kind
    "" where it kept no kinds)."""
    layers, runs = string_list(data.get("inputs", [])) or [], string_list(data.get("inputRuns", [])) or []
    kinds = string_list(data.get("inputKinds", [])) or []
    return [{"layer": layer, "run": runs[k] if k < len(runs) else "", "kind": kinds[k] if k < len(kinds) else ""}
            for k, layer in enumerate(layers)]


def string_list(value) -> list[str] | None:
    """A metadata list (a list or a Vt array) as strings; None for anything else (malformed metadata)."""
    if isinstance(value, (str, bytes, dict)) or not hasattr(value, "__iter__"):
        return None
    return [str(v) for v in value]


def read_provenance(prim: Usd.Prim) -> list[dict]:
    """Every FacedynProcessorAPI instance applied to prim, as dicts."""
    runs = []
    for schema in prim.GetAppliedSchemas():
        if not schema.startswith(PROCESSOR_API + ":"):
            continue
        name = schema.split(":", 1)[1]
        prefix = f"facedyn:processor:{name}:"

        def get(attr: str, prefix=prefix):
            return prim.GetAttribute(prefix + attr).Get()

        params = get("parameters")
        frame_range = get("frameRange")
        runs.append(
            {
                "processor": get("processor"),
                "role": get("role"),
                "version": get("version"),
                "parameters": json.loads(params) if params else {},
                "frameRange": list(frame_range) if frame_range is not None else None,
                "inputs": list(get("inputs") or []),
                "inputRuns": list(get("inputRuns") or []),
                "run": get("run"),
            }
        )
    return runs
