# Shared setup of the facedyn examples: source it, or run it to build prerequisites.
#
#   source "$(dirname "$0")/_setup.sh" "${1:-}"     # in an example: sets WORK, TAKE_DIR, ...
#   bash examples/_setup.sh WORK_DIR quasistatic     # build what a step needs, then exit
#
# Every ensure_* function is idempotent: it builds its result once and reuses it on the
# next run (delete the file or folder to rebuild it). Knobs, all optional:
#   FACEDYN_EXAMPLE_WORK      work folder when none is given (default: $TMPDIR/facedyn-examples)
#   FACEDYN_EXAMPLE_TAKES     glob of the demo protocol's takes to simulate (default: smile_*)
#   FACEDYN_EXAMPLE_TAKE      the take the examples process (default: smile_hop)
#   FACEDYN_EXAMPLE_OTHER     the take whose motion 05 retargets (default: smile_walk)
#   FACEDYN_EXAMPLE_F_EPOCHS  removal network F training epochs (default: 8)
#   FACEDYN_EXAMPLE_H_EPOCHS  synthesis network H training epochs (default: 20)
#   FACEDYN_EXAMPLE_F_SUBSAMPLE  fraction of F's training pairs drawn each epoch (default: 1)
#   FACEDYN_EXAMPLE_DATA      ../shared/data-like folder (default: ../shared/data beside the checkout)
#   PYTHON, USDFACEDYN        the interpreter and the CLI to use

EXAMPLES_DIR="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
REPO_DIR="$(dirname "$EXAMPLES_DIR")"
PYTHON="${PYTHON:-python3}"
USDFACEDYN="${USDFACEDYN:-usdfacedyn}"

WORK="${1:-${FACEDYN_EXAMPLE_WORK:-${TMPDIR:-/tmp}/facedyn-examples}}"
mkdir -p "$WORK"
WORK="$(cd "$WORK" && pwd)"

CORPUS="$WORK/corpus"
MODELS="$WORK/models"
TAKES_GLOB="${FACEDYN_EXAMPLE_TAKES:-smile_*}"
TAKE_NAME="${FACEDYN_EXAMPLE_TAKE:-smile_hop}"
OTHER_NAME="${FACEDYN_EXAMPLE_OTHER:-smile_walk}"
TAKE_DIR="$CORPUS/$TAKE_NAME"
OTHER_DIR="$CORPUS/$OTHER_NAME"
F_EPOCHS="${FACEDYN_EXAMPLE_F_EPOCHS:-8}"
H_EPOCHS="${FACEDYN_EXAMPLE_H_EPOCHS:-20}"
F_SUBSAMPLE="${FACEDYN_EXAMPLE_F_SUBSAMPLE:-1}"
DATA_DIR="${FACEDYN_EXAMPLE_DATA:-$(dirname "$REPO_DIR")/shared/data}"
REMOVAL_MODEL="$MODELS/face.removal"
SYNTHESIS_MODEL="$MODELS/face.synthesis"

step() { printf '\n== %s\n' "$*"; }
# Echo a command (on stderr, so that --json output stays clean), then run it.
show() { printf '$ %s\n' "$*" >&2; "$@"; }
fd() { show "$USDFACEDYN" "$@"; }

# note KEY MESSAGE: print MESSAGE once per script.
declare -A _NOTED=()
note() { [[ -n "${_NOTED[$1]:-}" ]] || { _NOTED[$1]=1; echo "$2"; }; }

ensure_corpus() {
    if [[ -f "$CORPUS/corpus.json" && -f "$TAKE_DIR/capture.usdc" && -f "$OTHER_DIR/capture.usdc" ]]; then
        note corpus "corpus: $CORPUS (already built)"
        return
    fi
    step "simulate a small corpus with known truth (demo protocol, takes '$TAKES_GLOB')"
    fd simulate --scale demo --only "$TAKES_GLOB" -o "$CORPUS"
}

# ensure_stabilized TAKE_DIR: stabilized.usdc (mode pursuit) attached to the take.
ensure_stabilized() {
    local dir="$1"
    ensure_corpus
    if [[ -f "$dir/stabilized.usdc" ]]; then return; fi
    step "stabilize $(basename "$dir") (mode pursuit)"
    fd stabilize "$dir/take.usda" -o "$dir/stabilized.usdc" --attach "$dir/take.usda" -q
}

ensure_removal_model() {
    ensure_corpus
    if [[ -f "$REMOVAL_MODEL" ]]; then
        note removal "removal model: $REMOVAL_MODEL (already trained; delete it to retrain)"
        return
    fi
    step "train the removal network F on the corpus (true skull, $F_EPOCHS epochs)"
    mkdir -p "$MODELS"
    fd train-removal "$CORPUS" -o "$REMOVAL_MODEL" --skull truth --epochs "$F_EPOCHS" --subsample "$F_SUBSAMPLE"
}

# ensure_quasistatic TAKE_DIR: quasistatic.usdc (remove) on top of stabilized.usdc.
ensure_quasistatic() {
    local dir="$1"
    ensure_stabilized "$dir"
    ensure_removal_model
    if [[ -f "$dir/quasistatic.usdc" ]]; then return; fi
    step "remove the secondary dynamics of $(basename "$dir")"
    fd remove "$dir/take.usda" --model "$REMOVAL_MODEL" -o "$dir/quasistatic.usdc" --attach "$dir/take.usda" -q
}

ensure_synthesis_model() {
    ensure_removal_model
    if [[ -f "$SYNTHESIS_MODEL" ]]; then
        note synthesis "synthesis model: $SYNTHESIS_MODEL (already trained; delete it to retrain)"
        return
    fi
    step "train the synthesis network H on the corpus (quasistatic from F, true skull, $H_EPOCHS epochs)"
    fd train-synthesis "$CORPUS" -o "$SYNTHESIS_MODEL" --quasistatic "$REMOVAL_MODEL" --skull truth --epochs "$H_EPOCHS"
}

# ensure_synthesized: the take's synthesized.hop.usdc (new dynamics under a procedural hop).
ensure_synthesized() {
    ensure_quasistatic "$TAKE_DIR"
    ensure_synthesis_model
    if [[ -f "$TAKE_DIR/synthesized.hop.usdc" ]]; then return; fi
    step "synthesize dynamics for a hop"
    fd synthesize "$TAKE_DIR/take.usda" --model "$SYNTHESIS_MODEL" --skull-motion hop \
        -o "$TAKE_DIR/synthesized.hop.usdc" --attach "$TAKE_DIR/take.usda" -q
}

# Run directly: `bash examples/_setup.sh WORK_DIR [corpus|stabilized|quasistatic|models|synthesized]...`
if [[ "${BASH_SOURCE[0]}" == "$0" ]]; then
    set -euo pipefail
    shift || true
    for what in "${@:-corpus}"; do
        case "$what" in
            corpus) ensure_corpus ;;
            stabilized) ensure_stabilized "$TAKE_DIR" ;;
            quasistatic) ensure_quasistatic "$TAKE_DIR" ;;
            models) ensure_synthesis_model ;;
            synthesized) ensure_synthesized ;;
            *) echo "_setup.sh: unknown step '$what' (corpus, stabilized, quasistatic, models, synthesized)" >&2; exit 2 ;;
        esac
    done
fi
