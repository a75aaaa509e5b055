#!/usr/bin/env bash
# 03 remove: train the removal network F on the corpus (with the simulator's true skull),
# then remove the secondary dynamics of the stabilized take: quasistatic.usdc holds the
# jiggle-free skin as points and the removed dynamics as primvars:facedyn:dynamicsOffset.
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/_setup.sh" "${1:-}"
ensure_stabilized "$TAKE_DIR"
ensure_removal_model  # usdfacedyn train-removal CORPUS -o face.removal --skull truth --epochs N

step "start from the stabilized take"
fd layers "$TAKE_DIR/take.usda"  # remove reads the stabilized take below its role

step "remove the dynamics that F predicts; attach quasistatic.usdc to the take"
fd remove "$TAKE_DIR/take.usda" --model "$REMOVAL_MODEL" -o "$TAKE_DIR/quasistatic.usdc" --attach "$TAKE_DIR/take.usda"

step "inspect: the take's role is now quasistatic and it carries offsets"
fd inspect "$TAKE_DIR/take.usda"
