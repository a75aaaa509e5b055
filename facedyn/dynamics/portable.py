"""A person-independent removal model: network F applied to any face, its setup built per take.

F is one network shared by every skin sample, so nothing in it is tied to the mesh it was
trained on: the face setup (skin samples, skull landmarks, rigid region, the propagation
to every vertex) can be rebuilt for the take at hand. A model whose metadata says
``info["face"] == PER_TAKE`` is such a model: loading it skips the topology check, and
`for_take` gives the model for one take, its setup built from the take's rest shape (the
take's rest points, as stabilize writes them, else its first frame).

F's inputs are vectors in the skull frame (landmark accelerations, skin velocities, rest
positions), and a take's skull frame is whatever its stabilization chose: an actor's rig
space, or the capture's own frame (Y up after import, facing any horizontal direction).
So the problem is turned into one face frame first (`FaceFrame`: up +Y, forward the
horizontal part of the face's mean outward normal, origin the centre of the rest face's
box in that frame), the same on every face, and the predicted offsets are turned back.
A constant change of skull frame, p' = C (p - o), changes the skull transforms
world = R p + t into world = (R C^T) p' + (t + R o): world points and the motion are
untouched, only the coordinates F reads change.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from facedyn.dynamics.face import FaceSetup
from facedyn.dynamics.modelfile import PER_TAKE
from facedyn.dynamics.samples import face_region
from facedyn.geometry import mesh, quaternion

UP = np.array([0.0, 1.0, 0.0])
FORWARD = np.array([0.0, 0.0, 1.0])
MIN_FACING = 0.05  # the face's mean normal must lean this much (of its area) to a horizontal side


def is_portable(model) -> bool:
    """Whether the model's face setup is built per take (a person-independent model)."""
    return model.kind == "removal" and model.info.get("face") == PER_TAKE


@dataclass(frozen=True)
class FaceFrame:
    """The change from a take's skull frame to the face frame F reads: p' = C (p - o)."""

    rotation: np.ndarray  # (3, 3) C, rows: the face's left, up and forward in the skull frame
    origin: np.ndarray  # (3,) o, the skull-space point that becomes the face frame's origin
    facing: str  # how forward was found (said in the layer's summary)

    def points(self, points) -> np.ndarray:
        """Skull-space points (..., 3) in the face frame, float64."""
        return (np.asarray(points, dtype=np.float64) - self.origin) @ self.rotation.T

    def transforms(self, translate: np.ndarray, orient: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The skull transforms that map face-frame points to the same world points."""
        rot = quaternion.to_matrix(orient)
        back = quaternion.conjugate(quaternion.from_matrix(self.rotation))
        return translate + rot @ self.origin, quaternion.normalize(quaternion.multiply(orient, np.broadcast_to(back, orient.shape)))

    def vectors_back(self, vectors: np.ndarray) -> np.ndarray:
        """Face-frame vectors (..., 3) in the take's skull frame, float32."""
        return np.matmul(vectors, self.rotation.astype(np.float32))


def face_frame(rest_points, topology, region=None) -> FaceFrame:
    """The face frame of a rest shape: up +Y of the skull frame, forward the horizontal part of
    the area-weighted mean outward normal of the `region` (default all) triangles, origin the
    centre of the rest shape's bounding box in that frame.

    Outward is away from the whole mesh's centroid. A face whose mean normal does not lean
    to any horizontal side (a closed head without a face region) keeps the skull frame's +Z.
    """
    rest = np.asarray(rest_points, dtype=np.float64)
    tri = topology.triangles().astype(np.int64)
    if len(tri):
        inside = np.zeros(len(rest), dtype=bool)
        inside[np.arange(len(rest)) if region is None else region] = True
        tri_in = tri[inside[tri].all(axis=1)]
        normals = mesh.face_normals(rest, tri_in)
        centres = rest[tri_in].mean(axis=1)
        if np.sum(np.einsum("ti,ti->t", normals, centres - rest.mean(axis=0))) < 0:  # wound inward
            normals = -normals
        area = 0.5 * np.linalg.norm(normals, axis=1).sum()
        mean = 0.5 * normals.sum(axis=0)
    else:
        area, mean = 0.0, np.zeros(3)
    horizontal = mean - UP * mean[1]
    if area > 0 and np.linalg.norm(horizontal) >= MIN_FACING * area:
        forward, facing = horizontal / np.linalg.norm(horizontal), "the face's mean outward normal"
    else:
        forward, facing = FORWARD, "the skull frame's +Z (the face's mean normal leans to no side)"
    rotation = np.stack([np.cross(UP, forward), UP, forward])
    turned = rest @ rotation.T
    centre = 0.5 * (turned.min(axis=0) + turned.max(axis=0))
    return FaceFrame(rotation, centre @ rotation, facing)


def face_setup(topology, rest_points, *, rigid_weights=None, face_vertices=None, uvs=None) -> tuple[FaceSetup, FaceFrame]:
    """(the face setup in its face frame, the frame) of a rest shape: what a person-independent
    F reads on this face, built the same way for training and for removal."""
    rest = np.asarray(rest_points, dtype=np.float64)
    region = face_region(len(rest), face_vertices, rigid_weights)
    frame = face_frame(rest, topology, region)
    setup = FaceSetup.build(topology, frame.points(rest), rigid_weights=rigid_weights, face_vertices=face_vertices, uvs=uvs)
    return setup, frame


def for_take(model, performance):
    """The person-independent `model` set up for one take (a Performance of its first frames
    with its rest points, rigid weights, face region and uvs where it has them): the same
    network, the take's own face setup and FaceFrame; ``info["rest"]`` says which rest was used."""
    from facedyn.dynamics.removal import SAMPLE_POSITIONS, sample_positions

    if not is_portable(model):
        raise ValueError("for_take needs a person-independent removal model (info['face'] == 'per-take')")
    if performance.rest_points is not None:
        rest, source = performance.rest_points, "the take's rest points"
    else:
        rest, source = performance.points[0], "the take's first frame"
    setup, frame = face_setup(performance.topology, rest, rigid_weights=performance.rigid_weights,
                              face_vertices=performance.face_vertices, uvs=performance.uvs)
    arrays = dict(model.arrays)
    if SAMPLE_POSITIONS in arrays:
        arrays[SAMPLE_POSITIONS] = sample_positions(setup)
    info = {**model.info, "rest": source, "facing": frame.facing}
    return replace(model, face=setup, arrays=arrays, info=info, frame=frame, warnings=list(model.warnings), _propagator=None)
