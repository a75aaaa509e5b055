#!/usr/bin/env bash
# 05 retarget: move another take's root (skull) motion onto the quasistatic take. The
# paper's way ("synthesis") aligns the source's skull trajectory to this take's skull
# and lets this actor's network H make the dynamics; the naive "delta-transfer" baseline
# copies the source's removed per-vertex offsets instead.
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/_setup.sh" "${1:-}"
ensure_quasistatic "$TAKE_DIR"
ensure_synthesis_model
# The source take: stabilized (its skull motion, for synthesis) and removed (its offsets,
# for delta-transfer).
ensure_quasistatic "$OTHER_DIR"

step "the source: $OTHER_NAME, stabilized and with its dynamics removed"
fd layers "$OTHER_DIR/take.usda"
step "the target: $TAKE_NAME, quasistatic"
fd layers "$TAKE_DIR/take.usda"  # retarget reads the quasistatic take below the variants

step "retarget by synthesis (the default method), attached to the target take"
fd retarget "$TAKE_DIR/take.usda" --source "$OTHER_DIR/take.usda" --model "$SYNTHESIS_MODEL" \
    -o "$TAKE_DIR/synthesized.retarget.usdc" --attach "$TAKE_DIR/take.usda"

step "the delta-transfer baseline (no model), written beside the take, not attached"
fd retarget "$TAKE_DIR/take.usda" --source "$OTHER_DIR/take.usda" --method delta-transfer \
    -o "$TAKE_DIR/synthesized.delta-transfer.usdc"

step "inspect the target take"
fd inspect "$TAKE_DIR/take.usda"
