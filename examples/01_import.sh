#!/usr/bin/env bash
# 01 import: an OBJ sequence becomes a canonical take (capture.usdc + take.usda),
# then `inspect` shows its layer stack and `validate` runs USD's and facedyn's checks.
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/_setup.sh" "${1:-}"

OBJ_DIR="$WORK/obj"
OUT_DIR="$WORK/imported"
mkdir -p "$OBJ_DIR" "$OUT_DIR"

step "write a small OBJ sequence of the built-in face: 6 frames, the jaw opening"
"$PYTHON" - "$OBJ_DIR" <<'PY'
import sys
from pathlib import Path

import numpy as np

from facedyn.io.obj import ObjMesh, write_obj
from facedyn.sim.default_face import default_face

folder = Path(sys.argv[1])
rig = default_face()
weights = np.zeros((6, rig.expression_count), np.float32)
weights[:, rig.shape_index("jawOpen")] = np.linspace(0.0, 0.8, 6)  # the jaw opens over 6 frames
frames = rig.evaluate(weights)
for i, points in enumerate(frames, start=1):
    write_obj(folder / f"face.{i:04d}.obj",
              ObjMesh(points, rig.topology.face_vertex_counts, rig.topology.face_vertex_indices, rig.uvs.values, rig.uvs.indices))
print(f"wrote {len(frames)} frames of {rig.point_count} points to {folder}/face.####.obj")
PY

step "import the folder's OBJ files (sorted by frame number) at 120 fps"
# Re-importing over an existing take is fine: the output is replaced atomically and
# capture.usdc is listed once in take.usda. A list of files works too (face.*.obj
# expanded by the shell).
fd import "$OBJ_DIR" --fps 120 -o "$OUT_DIR/capture.usdc"

step "inspect: layer stack, timing, roles, provenance"
fd inspect "$OUT_DIR/take.usda"

step "validate: USD's validators and facedyn's checks"
fd validate "$OUT_DIR/take.usda"

echo
echo "take: $OUT_DIR/take.usda"
