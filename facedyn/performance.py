"""facedyn's data model, as plain NumPy arrays (no pxr): a take (`Performance`), a skull
trajectory, the layer roles and the kernel backend names.

Every algorithm in facedyn works on a `Performance` (or on the arrays it holds) and never
on a USD stage; `facedyn.usd.take` converts between the two.

Conventions (used across the whole package):
- units are the take's (centimetres by default), Y up;
- a skull transform T(t) maps skull space to world space:
  ``world = R(q) @ skull + t`` with ``q`` a unit quaternion stored scalar-first
  ``(w, x, y, z)`` and ``t`` a translation;
- ``points`` are the skin in skull space (equal to world space while the skull is the
  identity, as in a freshly imported capture).
"""
from __future__ import annotations

import functools
import sys
from dataclasses import dataclass, field, replace

import numpy as np

from facedyn.geometry import quaternion

BACKENDS = ("auto", "opencl", "numpy")
"""Kernel backends: OpenCL where a device exists, the NumPy twins, or the machine's choice."""


@dataclass(frozen=True)
class Role:
    """What a layer's points are, and where that layer sits in a take's stack.

    A processor writes one role and reads the take composed from the layers of lower rank
    only, so whatever lies above it (results built on an earlier run) never feeds back.
    Roles of equal rank are variants: several may be stacked (synthesized.hop,
    synthesized.walk), the strongest shows.
    """

    name: str  # the token authored as facedyn:face:role and recorded in customLayerData
    rank: int  # position in the stack: a higher rank sits above (stronger)
    label: str  # what a menu calls the layers of this role
    variants: bool = False  # several layers of this role may coexist
    face_role: bool = True  # False: an overlay (e.g. heat maps) that leaves the face's role alone
    reads: str | None = None  # the role that must lie below a layer of this role (what it is computed from)
    file: str | None = None  # the file a take folder keeps a layer of this role in (default: <name>.usdc)

    def layer_file(self, label: str = "") -> str:
        """The file name of a layer of this role in a take folder; a labelled variant (a synthesis
        on the hop motion) puts its label after the first part: synthesized.hop.usdc, take.hop.preview.usdc."""
        name = self.file or f"{self.name}.usdc"
        if not label:
            return name
        first, _, rest = name.partition(".")
        return f"{first}.{label}.{rest}"


CAPTURED, STABILIZED, QUASISTATIC = "captured", "stabilized", "quasistatic"
SYNTHESIZED, RETARGETED, PREVIEW = "synthesized", "retargeted", "preview"
"""The built-in roles' names: code names a role through these constants, never a bare string."""

BUILTIN_ROLES = (
    Role(CAPTURED, 0, "capture", file="capture.usdc"),  # the base role: the capture every other layer is computed over; it sets the take's frames
    Role(STABILIZED, 10, "stabilized layers", reads=CAPTURED),
    Role(QUASISTATIC, 20, "quasistatic layers", reads=STABILIZED),
    Role(SYNTHESIZED, 30, "synthesized layers", variants=True, reads=QUASISTATIC),
    Role(RETARGETED, 30, "retargeted layers", variants=True, reads=QUASISTATIC),
    Role(PREVIEW, 40, "heat map", variants=True, face_role=False, file="take.preview.usdc"),  # preview wants *.preview.usdc
)
TAKE_ROOT_FILE = "take.usda"
"""The root layer a take folder is opened by (its subLayers are the layers above, by role)."""
ROLE_GROUP = "facedyn.roles"
"""Entry-point group through which third parties add roles (each entry point a `Role`)."""


def roles() -> dict[str, Role]:
    """Every known role by name, weakest first: the built-in ones and third parties'."""
    return dict(_roles_on(tuple(sys.path)))


@functools.lru_cache(maxsize=4)
def _roles_on(path: tuple[str, ...]) -> tuple[tuple[str, Role], ...]:
    """One scan of the installed distributions per search path (10-20 ms each; a command asks a dozen times)."""
    from importlib.metadata import entry_points

    found = {role.name: role for role in BUILTIN_ROLES}
    for entry_point in entry_points(group=ROLE_GROUP):
        role = entry_point.load()
        if not isinstance(role, Role):
            raise TypeError(f"entry point {entry_point.value} in {ROLE_GROUP} is not a facedyn Role")
        found.setdefault(role.name, role)
    return tuple(sorted(found.items(), key=lambda item: item[1].rank))


def role(name: str) -> Role:
    """The role called `name`, or a ValueError listing the known ones."""
    known = roles()
    if name not in known:
        raise ValueError(f"unknown role {name!r}; known: {', '.join(known)}")
    return known[name]


FACE_ROLES = tuple(r.name for r in BUILTIN_ROLES if r.face_role)


@dataclass
class Topology:
    """Polygon connectivity of the face mesh (USD's faceVertexCounts/Indices)."""

    face_vertex_counts: np.ndarray  # (P,) int32
    face_vertex_indices: np.ndarray  # (sum(counts),) int32

    @property
    def point_count(self) -> int:
        return int(self.face_vertex_indices.max()) + 1 if self.face_vertex_indices.size else 0

    def triangles(self) -> np.ndarray:
        """Fan-triangulate every polygon: (T, 3) int array, vectorized."""
        counts = np.asarray(self.face_vertex_counts, dtype=np.int64)
        starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
        tri_per_poly = np.maximum(counts - 2, 0)
        poly = np.repeat(np.arange(len(counts)), tri_per_poly)
        k = np.arange(tri_per_poly.sum()) - np.repeat(np.cumsum(tri_per_poly) - tri_per_poly, tri_per_poly)
        base = starts[poly]
        idx = np.asarray(self.face_vertex_indices, dtype=np.int64)
        return np.stack([idx[base], idx[base + k + 1], idx[base + k + 2]], axis=1).astype(np.int32)

    def fingerprint(self) -> str:
        """A short hash that identifies this connectivity (used to match models to meshes)."""
        import hashlib

        h = hashlib.sha1()
        h.update(np.ascontiguousarray(self.face_vertex_counts, dtype=np.int32).tobytes())
        h.update(np.ascontiguousarray(self.face_vertex_indices, dtype=np.int32).tobytes())
        return h.hexdigest()[:16]


@dataclass
class UVs:
    """Texture coordinates as authored by USD: values plus optional indices."""

    values: np.ndarray  # (K, 2) float32
    indices: np.ndarray | None  # (sum(counts),) int32 for faceVarying, None when not indexed
    interpolation: str  # "faceVarying" or "vertex"


@dataclass
class Performance:
    """A take as arrays: F frames of an N-point mesh plus its skull motion."""

    points: np.ndarray  # (F, N, 3) float32, skull space
    frames: np.ndarray  # (F,) float64 time codes (capture frame numbers)
    fps: float
    topology: Topology
    skull_translate: np.ndarray | None = None  # (F, 3) float64; None = identity
    skull_orient: np.ndarray | None = None  # (F, 4) float64 (w, x, y, z); None = identity
    uvs: UVs | None = None
    rest_points: np.ndarray | None = None  # (N, 3) float32, skull space
    rigid_weights: np.ndarray | None = None  # (N,) float32 in [0, 1]
    face_vertices: np.ndarray | None = None  # int32 indices of the face region
    skin_samples: np.ndarray | None = None  # int32 vertex indices
    alignment_vertices: np.ndarray | None = None  # (3,) eye corners L/R and under the nose
    landmarks: np.ndarray | None = None  # (L, 3) skull-space skull landmarks
    offsets: np.ndarray | None = None  # (F, N, 3) float32 dynamics offsets (skull space)
    solve_error: np.ndarray | None = None  # (F,) float32 per-frame stabilization error
    role: str = CAPTURED
    meters_per_unit: float = 0.01
    up_axis: str = "Y"
    metadata: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.points = np.asarray(self.points, dtype=np.float32)
        self.frames = np.asarray(self.frames, dtype=np.float64)
        if self.points.ndim != 3 or self.points.shape[2] != 3:
            raise ValueError(f"points must be (frames, points, 3), got {self.points.shape}")
        if len(self.frames) != len(self.points):
            raise ValueError(f"{len(self.frames)} frame numbers for {len(self.points)} frames of points")
        if self.role not in FACE_ROLES and self.role not in roles():
            raise ValueError(f"role must be one of {', '.join(roles())}, got {self.role!r}")

    @property
    def frame_count(self) -> int:
        return self.points.shape[0]

    @property
    def point_count(self) -> int:
        return self.points.shape[1]

    def skull(self) -> tuple[np.ndarray, np.ndarray]:
        """(translate (F,3), orient (F,4) wxyz), identity where the take has none."""
        f = self.frame_count
        t = self.skull_translate if self.skull_translate is not None else np.zeros((f, 3))
        q = self.skull_orient
        if q is None:
            q = np.zeros((f, 4))
            q[:, 0] = 1.0
        return np.asarray(t, dtype=np.float64), np.asarray(q, dtype=np.float64)

    def world_points(self) -> np.ndarray:
        """The skin in world space, T(t) applied to the skull-space points."""
        t, q = self.skull()
        if not t.any() and np.all(q == (1.0, 0.0, 0.0, 0.0)):  # a capture's static skull: world is skull space
            return self.points.astype(np.float32)
        rot_t = np.swapaxes(quaternion.to_matrix(q), 1, 2)
        world = np.empty(self.points.shape, dtype=np.float32)
        for a in range(0, self.frame_count, 1024):  # in float64, a block at a time (matmul: BLAS, unlike einsum)
            b = a + 1024
            world[a:b] = np.matmul(self.points[a:b].astype(np.float64), rot_t[a:b]) + t[a:b, None, :]
        return world

    def with_changes(self, **changes) -> "Performance":
        return replace(self, **changes)


@dataclass(frozen=True, eq=False)
class SkullTrajectory:
    """Rigid skull motion sampled at `fps` from time 0: translate (F,3) cm, orient (F,4) wxyz."""

    translate: np.ndarray
    orient: np.ndarray
    fps: float

    def __post_init__(self) -> None:
        translate = np.array(self.translate, dtype=np.float64)
        orient = np.array(self.orient, dtype=np.float64)
        if translate.ndim != 2 or translate.shape[1] != 3 or len(translate) == 0:
            raise ValueError(f"translate must be (frames >= 1, 3), got {translate.shape}")
        if orient.shape != (len(translate), 4):
            raise ValueError(f"orient must be ({len(translate)}, 4) to match translate, got {orient.shape}")
        if not (np.isfinite(translate).all() and np.isfinite(orient).all()):
            raise ValueError("translate and orient must be finite")
        norms = np.linalg.norm(orient, axis=1)
        if np.abs(norms - 1.0).max() > 1e-6:
            raise ValueError(f"orient must hold unit quaternions, norms range {norms.min():.6g}..{norms.max():.6g}")
        fps = float(self.fps)
        if not (np.isfinite(fps) and fps > 0):
            raise ValueError(f"fps must be positive, got {self.fps}")
        orient /= norms[:, None]
        translate.flags.writeable = False
        orient.flags.writeable = False
        object.__setattr__(self, "translate", translate)
        object.__setattr__(self, "orient", orient)
        object.__setattr__(self, "fps", fps)

    @property
    def frame_count(self) -> int:
        return self.translate.shape[0]

    @property
    def times(self) -> np.ndarray:
        """(F,) seconds of each frame."""
        return np.arange(self.frame_count) / self.fps


def skull_frame_id(rest_points: np.ndarray, topology: Topology) -> str:
    """What identifies a skull frame: the rest mesh a take was stabilized against (to 1 µm).

    Takes stabilized against one actor's neutral share this id; a take stabilized against
    its own estimated rest (its first frame's world) does not, and neither do two actors.
    """
    import hashlib

    h = hashlib.sha1(topology.fingerprint().encode())
    h.update(np.round(np.asarray(rest_points, dtype=np.float64), 4).astype(np.float32).tobytes())
    return h.hexdigest()[:16]


@dataclass
class Actor:
    """One actor's skull frame and face setup: everything later takes start from.

    `neutral` is the jiggle-free neutral face in the actor's skull space; it defines that
    space: every take stabilized against it lands in the same frame, and models trained in
    it refuse takes in another (`skull_frame_id`).
    """

    name: str
    neutral: np.ndarray  # (N, 3) float32, skull space, cm
    topology: Topology
    uvs: UVs | None = None
    rigid_weights: np.ndarray | None = None  # (N,) in [0, 1]; None until known
    face_vertices: np.ndarray | None = None
    skin_samples: np.ndarray | None = None
    alignment_vertices: np.ndarray | None = None  # (3,) eye corners L/R and under the nose
    landmarks: np.ndarray | None = None  # (L, 3) skull landmarks in skull space
    source: str = ""  # how it was made: "rig", "neutral" or "takes"

    def __post_init__(self) -> None:
        self.neutral = np.asarray(self.neutral, dtype=np.float32)
        n = self.topology.point_count
        if self.neutral.shape != (n, 3):
            raise ValueError(f"an actor's neutral must be ({n}, 3) for its topology, got {self.neutral.shape}")
        if not np.isfinite(self.neutral).all():
            raise ValueError("an actor's neutral must be finite")

    @property
    def skull_frame(self) -> str:
        return skull_frame_id(self.neutral, self.topology)
