"""The built-in face: a procedural head rig, so that facedyn runs without downloaded data.

The head is a quad sphere (closed, all quads, no poles) whose vertices are pulled toward
the face by a conformal warp, so the face gets most of the resolution. Its surface is a
radial function around the skull centre (an ellipsoid tapered at the jaw, plus smooth
compact bumps for nose, brows, eye sockets, lids, cheekbones, lips, chin and ears), which
keeps it embedded and outward-oriented for any bump heights. Expressions and identity
modes are smooth, compactly supported displacement fields with ARKit names matching
ICT-FaceKit's, so the same Live Link curves drive both rigs. Centimetres, Y up, face toward
+Z, the subject's left toward +X. Everything is deterministic arithmetic on arrays.
"""
from __future__ import annotations

import numpy as np

from facedyn.geometry import quaternion
from facedyn.performance import UVs, Topology
from facedyn.rig import FaceRig

RESOLUTION = 26  # quads along each edge of the quad sphere: 6 * 26**2 + 2 = 4,058 points

# The face's axis: straight ahead, tilted 15 degrees down toward the mouth; vertex density
# and the front uv tile are centred on it.
FACE_AXIS = np.array([0.0, -np.sin(np.radians(15.0)), np.cos(np.radians(15.0))])
FRONT_DENSITY = 0.6  # conformal warp factor: about 1 / 0.6**2 = 2.8x more vertices at the face
FRONT_TILE_DEGREES = 80.0  # polygons within this angle of FACE_AXIS go on uv tile 1001

HEAD_RADII = np.array([7.6, 10.6, 9.6])  # half width, height, depth (cm) of the skull
HEAD_ROUNDNESS = 2.3  # superellipsoid exponent: a little boxier (flatter face) than an ellipsoid
JAW_TAPER = 0.18  # the lower face is this much narrower at the chin than at the cheekbones

# (amplitude cm, centre x, y, radii x, y): radial bumps on the front of the head (z > 0).
FACE_BUMPS = (
    (0.8, 0.0, 0.6, 0.9, 2.2),  # nose bridge
    (1.8, 0.0, -2.4, 1.3, 1.7),  # nose tip
    (0.7, 1.2, -2.9, 0.9, 0.8),  # nostril wings
    (0.7, -1.2, -2.9, 0.9, 0.8),
    (0.55, 2.8, 2.2, 2.6, 1.0),  # brow ridge
    (0.55, -2.8, 2.2, 2.6, 1.0),
    (0.35, 0.0, 1.9, 1.2, 0.9),  # glabella
    (-1.1, 3.2, 0.4, 1.9, 1.4),  # eye sockets
    (-1.1, -3.2, 0.4, 1.9, 1.4),
    (0.55, 3.2, 0.3, 1.2, 0.8),  # closed lids over the eyeballs
    (0.55, -3.2, 0.3, 1.2, 0.8),
    (0.4, 4.6, -1.2, 2.0, 1.5),  # cheekbones
    (0.4, -4.6, -1.2, 2.0, 1.5),
    (0.25, 3.6, -4.3, 2.0, 2.0),  # cheeks
    (0.25, -3.6, -4.3, 2.0, 2.0),
    (0.55, 0.0, -5.3, 2.3, 0.8),  # upper lip
    (0.5, 0.0, -6.6, 2.0, 0.8),  # lower lip
    (-0.25, 0.0, -5.95, 2.2, 0.35),  # mouth line
    (0.7, 0.0, -8.9, 2.2, 1.6),  # chin
)
EAR = (1.3, -0.3, -0.6, 2.8, 1.6)  # amplitude, centre y, z, radii y, z (on both sides)

EYE = np.array([3.2, 0.35])  # left eye centre (x, y); the right one is mirrored
MOUTH_CORNER = np.array([2.2, -5.95])
JAW_HINGE = np.array([0.0, -0.8, 0.5])  # on the jaw's rotation axis (the x axis through it)
JAW_OPEN_DEGREES = 14.0
JAW_SIDE_DEGREES = 5.0  # jawLeft / jawRight: a swing about the vertical axis through the hinge
LANDMARK_XY = {
    "eye_corner_left": (4.4, 0.45),
    "eye_corner_right": (-4.4, 0.45),
    "eye_inner_left": (2.0, 0.35),
    "eye_inner_right": (-2.0, 0.35),
    "nose_tip": (0.0, -2.4),
    "nose_base": (0.0, -3.9),
}

# Left-side shapes that push a region of the face by a constant vector (cm at weight 1):
# name: (centre x, y), (radii x, y), plateau, displacement. The _R twins are mirrored.
PUSHES = {
    "browDown": ((2.6, 2.1), (2.2, 1.5), 0.2, (-0.25, -0.6, 0.1)),
    "browInnerUp": ((1.5, 2.4), (2.0, 1.8), 0.25, (0.0, 0.7, 0.05)),
    "browOuterUp": ((3.9, 2.4), (2.0, 1.6), 0.2, (0.0, 0.6, 0.0)),
    "eyeSquint": ((3.2, -0.35), (1.6, 0.9), 0.2, (0.0, 0.5, 0.15)),
    "mouthFrown": (tuple(MOUTH_CORNER), (1.6, 1.5), 0.15, (0.12, -0.56, -0.08)),
    "mouthStretch": (tuple(MOUTH_CORNER), (1.8, 1.6), 0.15, (0.6, -0.3, -0.15)),
    "mouthUpperUp": ((1.0, -5.3), (1.6, 0.9), 0.2, (0.0, 0.55, 0.1)),
    "noseSneer": ((1.1, -2.3), (1.2, 1.5), 0.2, (0.1, 0.55, 0.0)),
}


def default_face(resolution: int = RESOLUTION) -> FaceRig:
    """The built-in head rig; `resolution` quads per quad-sphere edge (6 r^2 + 2 points)."""
    if int(resolution) != resolution or resolution < 6:
        raise ValueError(f"resolution must be an integer >= 6, got {resolution!r}")
    resolution = int(resolution)
    sphere, quads = quad_sphere(resolution)
    directions = _pull_toward(sphere, FACE_AXIS, FRONT_DENSITY)
    neutral = _head(directions)
    names, fields = zip(*_expressions(neutral).items())
    expressions = np.stack(fields).astype(np.float32)
    moved = np.any(expressions != 0.0, axis=(0, 2))
    rigid = np.flatnonzero(_rigid_region(neutral) & ~moved)
    front = neutral[:, 2] > 4.0
    landmarks = {name: _nearest(neutral, front, xy) for name, xy in LANDMARK_XY.items()}
    topology = Topology(np.full(len(quads), 4, np.int32), quads.ravel().astype(np.int32))
    return FaceRig(
        name="DefaultFace",
        neutral=neutral.astype(np.float32),
        topology=topology,
        uvs=_two_tile_uvs(directions, quads),
        expression_names=names,
        expression_offsets=expressions,
        identity_modes=np.stack(_identity_modes(neutral)),
        face_vertices=np.flatnonzero(_face_region(neutral)),
        rigid_vertices=rigid,
        landmarks=landmarks,
        metadata={"source": "facedyn.sim.default_face", "resolution": resolution},
    )


def quad_sphere(n: int) -> tuple[np.ndarray, np.ndarray]:
    """Unit directions (6 n^2 + 2, 3) and outward, counter-clockwise quads (6 n^2, 4) of a cube's grid.

    Each cube face's (n+1)^2 lattice points are made with integer coordinates so that the
    points shared by two faces coincide exactly and merge; the equal-angle (tan) map then
    spreads them evenly over the sphere.
    """
    axes = np.eye(3, dtype=np.int64)
    lattice = np.arange(-n, n + 1, 2)
    a, b = np.meshgrid(lattice, lattice, indexing="ij")
    i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    first = (i * (n + 1) + j).ravel()  # lattice point (i, j); then (i+1, j), (i+1, j+1), (i, j+1)
    local_quads = first[:, None] + [0, n + 1, n + 2, 1]
    points, quads = [], []
    for face, (axis, sign) in enumerate((k, s) for k in range(3) for s in (1, -1)):
        u, v = axes[(axis + 1) % 3], axes[(axis + 2) % 3]
        if sign < 0:  # keep u x v along the outward normal, so quads wind counter-clockwise
            u, v = v, u
        points.append((sign * n * axes[axis] + a[..., None] * u + b[..., None] * v).reshape(-1, 3))
        quads.append(local_quads + face * (n + 1) ** 2)
    lattice_points, inverse = np.unique(np.concatenate(points), axis=0, return_inverse=True)
    spread = np.tan(lattice_points / n * (np.pi / 4))
    return spread / np.linalg.norm(spread, axis=1, keepdims=True), inverse.ravel()[np.concatenate(quads)]


def _pull_toward(directions: np.ndarray, axis: np.ndarray, k: float) -> np.ndarray:
    """Conformal sphere warp tan(theta'/2) = k tan(theta/2) about `axis` (k < 1 gathers points there)."""
    along = directions @ axis
    across = directions - along[:, None] * axis
    sin_theta = np.linalg.norm(across, axis=1)
    theta = np.arctan2(sin_theta, along)
    warped = 2.0 * np.arctan2(k * np.sin(theta / 2), np.cos(theta / 2))
    scale = np.sin(warped) / np.where(sin_theta > 0, sin_theta, 1.0)
    return np.cos(warped)[:, None] * axis + scale[:, None] * across


def _smoothstep(t: np.ndarray) -> np.ndarray:
    t = np.clip(t, 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


def _bump(p: np.ndarray, centre, radii, plateau: float = 0.0) -> np.ndarray:
    """Smooth bump of compact support: 1 inside `plateau` of the (anisotropic) radius, 0 outside it.

    Compact support makes every feature and expression exactly local (and sparse).
    """
    d = (p[:, : len(centre)] - np.asarray(centre)) / np.asarray(radii)
    return _smoothstep((1.0 - np.sum(d * d, axis=1)) / (1.0 - plateau))


def _front(p: np.ndarray) -> np.ndarray:
    """1 on the face side of the head (z > 4 cm), 0 behind z = 0."""
    return _smoothstep(p[:, 2] / 4.0)


def _head(directions: np.ndarray) -> np.ndarray:
    """Neutral points: tapered superellipsoid skull, then radial bumps for the features."""
    q = np.abs(directions) / HEAD_RADII
    skull = directions * np.sum(q**HEAD_ROUNDNESS, axis=1, keepdims=True) ** (-1.0 / HEAD_ROUNDNESS)
    skull[:, 0] *= 1.0 - JAW_TAPER * _smoothstep((-1.0 - skull[:, 1]) / 9.0)
    height = np.zeros(len(skull))
    front = _front(skull)
    for amplitude, x, y, rx, ry in FACE_BUMPS:
        height += amplitude * front * _bump(skull, (x, y), (rx, ry))
    amplitude, y, z, ry, rz = EAR
    side = np.abs(skull[:, 0]) > 4.0
    height += amplitude * side * _bump(skull[:, 1:], (y, z), (ry, rz))
    radius = np.linalg.norm(skull, axis=1)
    return skull * ((radius + height) / radius)[:, None]


def _mirror(field_left, p: np.ndarray) -> np.ndarray:
    """The right-side twin of a left-side displacement field (mirror in x)."""
    mirrored = p * [-1.0, 1.0, 1.0]
    return field_left(mirrored) * [-1.0, 1.0, 1.0]


def _jaw_weight(p: np.ndarray) -> np.ndarray:
    """How much each point follows the jaw: 1 below the lips and in front of the ears, 0 above."""
    rel = p - JAW_HINGE
    below = np.degrees(np.arctan2(-rel[:, 1], rel[:, 2]))  # angle below the hinge's forward direction
    return _smoothstep((below - 28.0) / 4.5) * _smoothstep((p[:, 2] - 0.5) / 3.0)


def _push(p: np.ndarray, centre, radii, plateau: float, vector) -> np.ndarray:
    """A constant displacement over one bump of the face: the building block of most shapes."""
    return (_bump(p, centre, radii, plateau) * _front(p))[:, None] * np.asarray(vector)


def _expressions(p: np.ndarray) -> dict[str, np.ndarray]:
    """ARKit-named expression offsets (cm at weight 1) on the neutral points p."""
    jaw = _jaw_weight(p)[:, None]

    def jaw_turn(axis, degrees):
        rotation = quaternion.to_matrix(quaternion.from_axis_angle(np.asarray(axis, float), np.radians(degrees)))
        return jaw * ((p - JAW_HINGE) @ rotation.T + JAW_HINGE - p)

    def smile(q):
        return _push(q, MOUTH_CORNER, (1.8, 1.6), 0.15, (0.6, 0.98, -0.45)) + _push(q, (3.3, -4.0), (1.8, 1.8), 0.0, (0.0, 0.4, 0.1))

    def blink(q):
        lid = _bump(q, EYE, (1.5, 1.2), 0.3) * _front(q)
        upper = _smoothstep((q[:, 1] - (EYE[1] - 0.6)) / 1.0)
        return lid[:, None] * np.stack([np.zeros(len(q)), 0.15 - 1.05 * upper, 0.15 * upper], axis=1)

    def cheek_puff(q):
        outward = q - [0.0, -4.8, 3.0]  # from inside the mouth
        return 1.2 * _push(q, (3.6, -4.6), (2.6, 2.4), 0.0, 1.0) * outward / np.linalg.norm(outward, axis=1, keepdims=True)

    mouth = _push(p, (0.0, -5.95), (3.0, 2.0), 0.3, 1.0)
    zeros = np.zeros(len(p))
    opening = np.clip((p[:, 1] + 5.95) / 0.65, -1.0, 1.0)  # +1 on the upper lip, -1 on the lower
    shapes = {
        "jawOpen": jaw_turn([1, 0, 0], JAW_OPEN_DEGREES),
        "jawLeft": jaw_turn([0, 1, 0], JAW_SIDE_DEGREES),
        "jawRight": jaw_turn([0, 1, 0], -JAW_SIDE_DEGREES),
        "mouthPucker": mouth * np.stack([-0.3 * p[:, 0], zeros, zeros + 1.0], axis=1),
        "mouthFunnel": mouth * np.stack([-0.15 * p[:, 0], 0.35 * opening, zeros + 0.7], axis=1),
    }
    for name, ((x, y), radii, plateau, (dx, dy, dz)) in PUSHES.items():
        shapes[f"{name}_L"] = _push(p, (x, y), radii, plateau, (dx, dy, dz))
        shapes[f"{name}_R"] = _push(p, (-x, y), radii, plateau, (-dx, dy, dz))
    for name, left in (("mouthSmile", smile), ("eyeBlink", blink), ("cheekPuff", cheek_puff)):
        shapes[f"{name}_L"] = left(p)
        shapes[f"{name}_R"] = _mirror(left, p)
    return dict(sorted(shapes.items()))


def _identity_modes(p: np.ndarray) -> list[np.ndarray]:
    """Smooth whole-head variations, each about one standard deviation of real faces (0.4-0.7 cm)."""
    zeros = np.zeros(len(p))
    width = np.stack([0.06 * p[:, 0], zeros, zeros], axis=1)
    jaw_length = np.stack([zeros, -0.7 * _smoothstep((-3.0 - p[:, 1]) / 6.0) * _smoothstep((p[:, 2] + 3.0) / 5.0), zeros], axis=1)
    nose_size = 0.15 * (_bump(p, (0.0, -1.5), (2.0, 3.2), 0.2) * _front(p))[:, None] * (p - [0.0, -1.5, 7.5])
    depth = np.stack([zeros, zeros, 0.05 * p[:, 2]], axis=1)
    radial = p / np.linalg.norm(p, axis=1, keepdims=True)
    cheekbones = 0.35 * ((_bump(p, (4.3, -1.6), (2.2, 1.8)) + _bump(p, (-4.3, -1.6), (2.2, 1.8))) * _front(p))[:, None] * radial
    return [width, jaw_length, nose_size, depth, cheekbones]


def _face_region(p: np.ndarray) -> np.ndarray:
    """The soft face: the front of the head below the hairline."""
    return (p[:, 2] > 1.5) & (p[:, 1] < 5.0)


def _rigid_region(p: np.ndarray) -> np.ndarray:
    """Skin on bone: back and top of the head, ears, nose bridge, upper forehead."""
    back_or_top = (p[:, 2] < -1.0) | (p[:, 1] > 5.5)
    ears = (np.abs(p[:, 0]) > 6.0) & (np.abs(p[:, 1] - EAR[1]) < EAR[3]) & (np.abs(p[:, 2] - EAR[2]) < EAR[4])
    nose_bridge = (np.abs(p[:, 0]) < 0.7) & (p[:, 1] > -1.2) & (p[:, 1] < 0.8) & (p[:, 2] > 4.0)
    forehead = (p[:, 1] > 4.2) & (p[:, 2] > 0.0)
    return back_or_top | ears | nose_bridge | forehead


def _nearest(p: np.ndarray, candidates: np.ndarray, xy) -> int:
    """The candidate vertex closest to a point of the face seen from the front."""
    index = np.flatnonzero(candidates)
    return int(index[np.argmin(np.sum((p[index, :2] - xy) ** 2, axis=1))])


def _two_tile_uvs(directions: np.ndarray, quads: np.ndarray) -> UVs:
    """faceVarying uvs: the face on tile 1001 and the back of the head on 1002, cut between them.

    Each tile is a stereographic (conformal) projection of its half of the sphere, from the
    face axis for the front and the opposite axis (mirrored, to keep uvs counter-clockwise)
    for the back, so neither tile overlaps itself.
    """
    n = len(directions)
    centroids = directions[quads].mean(axis=1)
    centroids /= np.linalg.norm(centroids, axis=1, keepdims=True)
    front = centroids @ FACE_AXIS > np.cos(np.radians(FRONT_TILE_DEGREES))
    x_axis = np.array([1.0, 0.0, 0.0])
    up = np.cross(FACE_AXIS, x_axis)
    corner_ids = np.where(front[:, None], quads, quads + n).ravel()
    used = np.unique(corner_ids)
    values = np.empty((2 * n, 2))
    for tile, (axis, right, rows) in enumerate(((FACE_AXIS, x_axis, used[used < n]), (-FACE_AXIS, -x_axis, used[used >= n] - n))):
        d = directions[rows]
        along = d @ axis
        across = np.stack([d @ right, d @ up], axis=1)
        radius = np.tan(np.arctan2(np.linalg.norm(across, axis=1), along) / 2.0)
        unit = across / np.maximum(np.linalg.norm(across, axis=1, keepdims=True), 1e-12)
        values[rows + tile * n] = [0.5 + tile, 0.5] + 0.48 * (radius / radius.max())[:, None] * unit
    return UVs(values=values[used].astype(np.float32), indices=np.searchsorted(used, corner_ids).astype(np.int32), interpolation="faceVarying")
