"""A small take with one layer per role, written the way the runner writes them.

Each role's layer offsets the capture's points by its own constant, so which layer a
composed read shows is plain from the points; the preview overlay writes colours only.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
from pxr import Sdf

from facedyn.performance import Topology, role
from facedyn.usd import schema
from facedyn.usd.layers import LayerContent, write_layer
from facedyn.usd.rootedit import attach
from facedyn.usd.take import read_take_below
from facedyn.usd.timing import Timing
from usd_fixtures import grid_mesh

FRAMES = np.arange(1001, 1011, dtype=np.float64)
TIMING = Timing(24.0, 24.0, FRAMES[0], FRAMES[-1])
PROCESSOR = {"captured": "import", "stabilized": "stabilize", "quasistatic": "remove", "synthesized": "synthesize",
             "retargeted": "retarget", "preview": "preview"}
OFFSET = {"captured": 0.0, "stabilized": 1.0, "quasistatic": 2.0, "synthesized": 3.0, "retargeted": 4.0, "preview": 5.0}


def base_points() -> np.ndarray:
    points, _, _ = grid_mesh(4)
    return np.stack([points + 0.01 * i for i in range(len(FRAMES))]).astype(np.float32)


def make_capture(folder: Path) -> tuple[Path, Path]:
    """capture.usdc and take.usda (created through attach, as an import does)."""
    points, counts, indices = grid_mesh(4)
    content = LayerContent(frames=FRAMES, points=base_points(), topology=Topology(counts, indices),
                           face=schema.FaceAttributes(role="captured"), skull=schema.SkullAttributes(solver="identity"))
    source = folder / "source.txt"
    source.write_text("the studio's mesh cache")
    prov = schema.Provenance("import", "test 1", {"fps": 24.0}, (FRAMES[0], FRAMES[-1]), [source], role="captured")
    capture = write_layer(folder / "capture.usdc", content, TIMING, prov, define=True)
    root = folder / "take.usda"
    attach(root, capture, "captured", create_with=TIMING)
    return root, capture


def write_role_layer(root: Path, name: str, role_name: str, value: float | None = None, params: dict | None = None,
                     frames: np.ndarray = FRAMES, extra_inputs: list | None = None, processor: str | None = None) -> Path:
    """Write a layer of role_name computed from what lies below that role in root (not attached)."""
    _, source = read_take_below(root, role_name)
    keep = np.isin(FRAMES, frames)
    value = OFFSET.get(role_name, 0.0) if value is None else value
    values = base_points()[keep] + value
    if role(role_name).face_role:
        content = LayerContent(frames=FRAMES[keep], points=values, face=schema.FaceAttributes(role=role_name))
    else:  # an overlay such as the heat map: colours only
        content = LayerContent(frames=FRAMES[keep], display_color=values / values.max(), face=schema.FaceAttributes(role=None))
    prov = schema.Provenance(processor or PROCESSOR.get(role_name, role_name), "test 1", params or {}, (FRAMES[keep][0], FRAMES[keep][-1]),
                             list(source.inputs) + list(extra_inputs or []), role=role_name)
    return write_layer(root.parent / name, content, TIMING, prov)


def build_take(folder: Path) -> Path:
    """take.usda: preview > synthesized.hop > quasistatic > stabilized > capture, each computed over the ones below."""
    root, _ = make_capture(folder)
    for name, role_name in (("stabilized.usdc", "stabilized"), ("quasistatic.usdc", "quasistatic"),
                            ("synthesized.hop.usdc", "synthesized"), ("take.preview.usdc", "preview")):
        attach(root, write_role_layer(root, name, role_name), role_name)
    return root


def sublayers(root: Path) -> list[str]:
    layer = Sdf.Layer.OpenAsAnonymous(str(root))
    return list(layer.subLayerPaths)
