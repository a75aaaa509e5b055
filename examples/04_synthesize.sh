#!/usr/bin/env bash
# 04 synthesize: train the synthesis network H (its quasistatic targets come from the
# removal model, the paper's way), then give the quasistatic take new secondary dynamics
# for a new skull motion: a procedural hop, and real mocap (CMU 131_03) when the shared
# data is there. Each result is its own synthesized.<name>.usdc layer on the same take.
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/_setup.sh" "${1:-}"
ensure_quasistatic "$TAKE_DIR"
ensure_synthesis_model  # usdfacedyn train-synthesis CORPUS -o face.synthesis --quasistatic face.removal --skull truth

step "start from the quasistatic take"
fd layers "$TAKE_DIR/take.usda"  # synthesize reads the quasistatic take below every synthesized variant

step "synthesize under a procedural hop (walk, run, still, platform:9hz work the same way)"
fd synthesize "$TAKE_DIR/take.usda" --model "$SYNTHESIS_MODEL" --skull-motion hop \
    -o "$TAKE_DIR/synthesized.hop.usdc" --attach "$TAKE_DIR/take.usda"

BVH="$DATA_DIR/cmu-mocap/131_03.bvh"
if [[ -f "$BVH" ]]; then
    step "synthesize under real head motion: the Head joint of CMU mocap 131_03"
    fd synthesize "$TAKE_DIR/take.usda" --model "$SYNTHESIS_MODEL" --skull-motion "$BVH" --joint Head \
        -o "$TAKE_DIR/synthesized.cmu131_03.usdc" --attach "$TAKE_DIR/take.usda"
else
    echo "(no $BVH: skipping the mocap-driven synthesis)"
fi

step "inspect: the synthesized variants stack on the quasistatic take (the strongest one shows)"
fd inspect "$TAKE_DIR/take.usda"
