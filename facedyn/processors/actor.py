"""`usdfacedyn actor`: make an actor asset, the one skull frame all of an actor's takes share.

Three ways, by what the studio has:
- `--from rig`: a UsdSkel blend-shape rig (its neutral, rigid and face vertex sets, eye
  corners). The actor lives in the rig's own space, so networks trained on `simulate --rig`
  of that rig apply to the actor's takes unchanged.
- `--from neutral`: one neutral capture or scan (a USD mesh, its first time sample, or a
  take's first frame): the neutral defines the skull frame; the rigid region is unknown.
- `--from takes`: several of the actor's captures: the rigid region and a jiggle-free
  neutral are estimated from the data (the vertices that stay in the rigid mode).
"""
from __future__ import annotations

from functools import partial
from pathlib import Path

import numpy as np

from facedyn.errors import UsageError
from facedyn.processors.base import FileOutput, Parameter, Plan, Processor, Reads, Request, Writes
from facedyn.progress import Progress


class ActorProcessor(Processor):
    name = "actor"
    version = "1"
    summary = "make an actor asset (actor.usda): the skull frame, neutral and face setup every take of the actor shares"
    reads = Reads("sources", metavar="SRC", help="a blend-shape rig, a neutral mesh or take, or the actor's takes (see --from)")
    writes = Writes("file", metavar="ACTOR", help="the actor asset to write (e.g. actor.usda)")
    parameters = (
        Parameter("from", str, "rig", "what SRC is: a UsdSkel blend-shape rig, one neutral mesh or take, or the actor's takes",
                  ("rig", "neutral", "takes")),
        Parameter("name", str, "", "the actor's name (default: the output file's stem)"),
        Parameter("mesh", str, "", "prim path of the mesh in SRC (default: the only rig mesh / animated mesh)"),
        Parameter("samples", int, 344, "skin samples chosen for the networks", minimum=1, maximum=100000),
    )

    def prepare(self, request: Request) -> Plan:
        params = request.params
        if not request.output.suffix.lower().startswith(".usd"):
            raise UsageError(f"{request.output}: name the actor asset *.usda (or .usdc)")
        source = params["from"]
        if source != "takes" and len(request.inputs) != 1:
            raise UsageError(f"--from {source} reads one SRC, got {len(request.inputs)}")
        name = params["name"] or request.output.stem
        if source == "rig":
            actor = _from_rig(request.inputs[0], params, name)
        elif source == "neutral":
            actor = _from_neutral(request.inputs[0], params, name)
        else:
            actor = _from_takes(request.inputs, params, name)
        description = {"from": source, "sources": [str(p) for p in request.inputs], "points": int(len(actor.neutral)),
                       "rigid_vertices": int(np.count_nonzero(actor.rigid_weights >= 0.99)) if actor.rigid_weights is not None else None,
                       "skin_samples": int(len(actor.skin_samples)) if actor.skin_samples is not None else None}
        return Plan(description, actor)

    def run(self, plan: Plan, progress: Progress) -> FileOutput:
        from facedyn.usd.actor_asset import write_actor

        actor = plan.state
        return FileOutput(partial(write_actor, actor=actor), {**plan.description, "skull_frame": actor.skull_frame})


def _face_setup(actor_fields: dict, sample_count: int):
    """Skin samples and skull landmarks chosen the way the trainers choose them."""
    from facedyn.dynamics.face import FaceSetup

    return FaceSetup.build(actor_fields["topology"], actor_fields["neutral"], rigid_weights=actor_fields.get("rigid_weights"),
                           face_vertices=actor_fields.get("face_vertices"), sample_count=sample_count)


def _actor(name: str, source: str, sample_count: int, **fields):
    from facedyn.performance import Actor

    setup = _face_setup(fields, sample_count)
    return Actor(name=name, source=source, skin_samples=setup.samples, landmarks=setup.landmarks.astype(np.float32), **fields)


def _from_rig(path: Path, params: dict, name: str):
    from facedyn.rig import alignment_vertices
    from facedyn.usd.blendshape_rig import read_blendshape_rig

    rig = read_blendshape_rig(path, params["mesh"] or None)
    return _actor(name, "rig", params["samples"], neutral=rig.neutral, topology=rig.topology, uvs=rig.uvs,
                  rigid_weights=rig.rigid_weights, face_vertices=rig.face_vertices, alignment_vertices=alignment_vertices(rig))


def _from_neutral(path: Path, params: dict, name: str):
    """The first frame of a take, or the first sample of a mesh (static or animated), made canonical like import does."""
    from facedyn.usd.source import read_usd_mesh

    mesh = read_usd_mesh(path, params["mesh"], first_frame_only=True)
    return _actor(name, "neutral", params["samples"], neutral=mesh.points[0], topology=mesh.topology, uvs=mesh.uvs)


def _from_takes(paths: list[Path], params: dict, name: str):
    """The rigid mode found on the first take (checked to be the skull's, not a sliding block's, on its middle
    frames: facedyn.stabilize.rigidity.discover_rigid_mode), each later take registered to it and merged in."""
    from facedyn.stabilize.rigidity import discover_rigid_mode, estimate_rigidity

    first, found = None, None
    for path in paths:
        source, points = _rigidity_sample(path, params["mesh"])
        if first is not None and source.topology.fingerprint() != first.topology.fingerprint():
            raise UsageError(f"{path}: its mesh topology differs from {paths[0]}'s; an actor has one topology")
        if found is None:
            model, _ = discover_rigid_mode(points, source.timing.frames_per_second, _middle_frames(source))
        else:
            model = estimate_rigidity(points, prior=found)
        found, first = (model if found is None else found.merge(model)), first or source
    return _actor(name, "takes", params["samples"], neutral=found.rest, topology=first.topology, uvs=first.uvs,
                  rigid_weights=found.weights.astype(np.float32))


def _rigidity_sample(path: Path, mesh: str):
    """A capture's source and the evenly spaced frames rigidity statistics read (all of a short take),
    read a frame at a time, so a long take is never whole in memory."""
    from facedyn.stabilize.rest import sample_frames
    from facedyn.stabilize.rigidity import SAMPLE_FRAMES
    from facedyn.usd.source import open_mesh_source

    source = open_mesh_source(path, mesh)
    codes = source.time_codes[sample_frames(len(source.time_codes), SAMPLE_FRAMES)]
    return source, np.concatenate([source.read(codes[i:i + 1]) for i in range(len(codes))])


def _middle_frames(source):
    """The consecutive frames in the middle of a capture that a discovered mode's inertia is checked on, dropped
    frames bridged."""
    from facedyn.stabilize.dropped import bridge_dropped, tracked_frames
    from facedyn.stabilize.rigidity import middle_window

    codes = source.time_codes[middle_window(len(source.time_codes), source.timing.frames_per_second)]
    window = source.read(codes)
    return bridge_dropped(window, tracked_frames(window))
