#!/usr/bin/env bash
# 06 preview: a *.preview.usdc layer of primvars:displayColor heat maps (each vertex's
# dynamics offset along its normal: green out, red in, grey zero) attached on top of the
# synthesized take, and how to look at it in usdview.
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/_setup.sh" "${1:-}"
ensure_synthesized  # synthesized.hop.usdc over quasistatic.usdc (see 04)

step "preview shows the strongest result below it: mute 05's retargeted layer on disk (if any) so the hop shows"
if [[ -f "$TAKE_DIR/synthesized.retarget.usdc" ]] && grep -q "synthesized.retarget.usdc" "$TAKE_DIR/take.usda"; then
    fd layers "$TAKE_DIR/take.usda" --mute "$TAKE_DIR/synthesized.retarget.usdc"
else
    fd layers "$TAKE_DIR/take.usda"
fi

step "write the heat-map layer (colour range: the take's 99.5th percentile; --range-mm fixes it)"
fd preview "$TAKE_DIR/take.usda" -o "$TAKE_DIR/hop.preview.usdc" --attach "$TAKE_DIR/take.usda"

step "usdview and DCCs build USD's schema registry before facedyn runs: give them facedyn's plugins"
fd env

cat <<TXT

To look at it:
    eval "\$($USDFACEDYN env)"
    usdview $TAKE_DIR/take.usda
Play the timeline to see the heat map move. usdview's "facedyn" menu (the plugin that
the env line registers) mutes and unmutes result layers, one entry per role: "Toggle heat
map" shows the plain surface, "Toggle synthesized layers" the quasistatic take under the
hop's dynamics, "Show all facedyn layers" brings everything back. Nothing on disk changes
(`usdfacedyn layers TAKE --mute/--unmute LAYER` does the same on disk);
07 does the same from Python with Usd.Stage.MuteLayer. (pip's usd-core has no usdview;
a full USD build has it.)
TXT
