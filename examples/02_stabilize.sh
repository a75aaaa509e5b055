#!/usr/bin/env bash
# 02 stabilize: solve a corpus take's rigid skull motion by mode pursuit (attached to the
# take as stabilized.usdc) and by the three-point baseline (a separate, unattached layer);
# compare their median solve errors, and their errors against the simulator's true skull.
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/_setup.sh" "${1:-}"
ensure_corpus

step "start from the captured take: take.usda lists only capture.usdc"
fd layers "$TAKE_DIR/take.usda"  # stabilize reads the capture below its role, whatever lies above; a re-run replaces its layer

step "mode pursuit (the default method), attached to take.usda as its strongest layer"
fd stabilize "$TAKE_DIR/take.usda" -o "$TAKE_DIR/stabilized.usdc" --attach "$TAKE_DIR/take.usda" --json > "$WORK/stabilize.mode-pursuit.json"

step "the three-point baseline (eye corners + under the nose), written beside the take, not attached"
fd stabilize "$TAKE_DIR/take.usda" -o "$TAKE_DIR/three_point.usdc" --method three-point --json > "$WORK/stabilize.three-point.json"

step "compare: median solve error (from --json) and error against the true skull"
"$PYTHON" - "$WORK" "$TAKE_DIR" <<'PY'
import json
import sys
from pathlib import Path

from facedyn.evaluation import stabilization_errors
from facedyn.usd.corpus_files import read_truth
from facedyn.usd.take import read_layers

work, take = Path(sys.argv[1]), Path(sys.argv[2])
truth = read_truth(take)
print(f"{'method':<14}{'median solve error (cm)':>26}{'median vertex error vs truth (cm)':>36}")
for method, layer in (("mode-pursuit", "stabilized.usdc"), ("three-point", "three_point.usdc")):
    report = json.loads((work / f"stabilize.{method}.json").read_text())
    solve = report["summary"]["median_solve_error_cm"]
    # Compose the solved layer over the capture in memory (the three-point layer is not attached).
    solved = read_layers([take / layer, take / "capture.usdc"])
    errors = stabilization_errors(*solved.skull(), truth.skull_translate, truth.skull_orient, truth.points + truth.offsets)
    print(f"{method:<14}{solve:>26.5f}{errors['median_vertex_cm']:>36.5f}")
PY

step "the take now composes the stabilized layer over the capture"
fd inspect "$TAKE_DIR/take.usda"
