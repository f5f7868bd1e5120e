#!/usr/bin/env bash
# From the simulated factory to the shipped ONNX model sets, with no manual step:
#
#   1. spwi-sim dataset (scenarios 1-3): the spatial graphs, as the paper builds them
#      (image distances, appearance) and as our sets do (floor distances, each node's
#      floor relations: --node-features floor_relations, core/src/graph.rs);
#   2. train_gcn.py: a GCN on each, exported to ONNX (`paper` ships the first, every
#      other set the second);
#   3. spwi-sim dataset --gcn gcn.onnx: the temporal rows, with the embeddings the
#      agent's own Rust code computes from the paper's exported GCN (only `paper`'s
#      rows read them);
#   4. train_temporal.py per model set: ego-GRU, collective-GRU (and the 1D-CNN baseline
#      for the default set), temperature scaling, export, checks, manifest. `paper` is
#      the paper's design (rows: embeddings and keypoints); `relations` adds the
#      worker's relations to the mapped stations (core/src/floor/); `default` also
#      reads where the worker's body faces against each station; `peer-set` is
#      `relations` that pools one relation block per peer heard in its collective GRU;
#      all share the GCN and data.
#
# Usage: models/train.sh            (all sets; see models/README.md for the time)
#        SETS="default" models/train.sh
# Settings (environment): EPISODES per scenario (300), SEED (1), LAYOUTS (the floors
# trained on: train:0..300, one episode after another on each; never the evaluation's
# held-out family), TRACK_SHARE and WARM_SHARE (the shares of episodes whose cameras
# track the worker, and whose fleet starts from the maps of up to WARM_UP_MAX s of work
# on the floor: sim/src/training_mix.rs), SPWI_TRAIN_VENV,
# SPWI_TRAIN_DATA (where the exports go, ~5 GB), MODELS_OUT (where the sets go:
# models/), STAGE2_ONLY=1 (reuse the GCNs and temporal exports already in
# SPWI_TRAIN_DATA), GCN_FROM="models/SET ..." (take each named shipped set's GCN, which
# was trained on the same data, for the graphs it reads — its manifest's node_features
# — instead of training one; e.g. GCN_FROM="models/paper models/default" trains none),
# CARGO_TARGET_DIR.
set -euo pipefail
cd "$(dirname "$0")/.."

EPISODES="${EPISODES:-300}"
SEED="${SEED:-1}"
LAYOUTS="${LAYOUTS:-train:0..300}"
TRACK_SHARE="${TRACK_SHARE:-0}"
WARM_SHARE="${WARM_SHARE:-0}"
WARM_UP_MAX="${WARM_UP_MAX:-0}"
SETS="${SETS:-paper default relations peer-set w10-h10 w30-h30 w10-h10-f5 w10-h10-f3}"
VENV="${SPWI_TRAIN_VENV:-$HOME/.cache/spwi/train-venv}"
DATA="${SPWI_TRAIN_DATA:-$HOME/.cache/spwi/train-data}"
OUT="$(realpath -m "${MODELS_OUT:-models}")"
export CARGO_TARGET_DIR="${CARGO_TARGET_DIR:-$HOME/.cache/spwi/target}"
step() { printf '\n=== %s (%s)\n' "$*" "$(date +%T)"; }
started=$SECONDS

step "training venv (PyTorch CPU, onnx, onnxruntime)"
[ -x "$VENV/bin/python" ] || python3 -m venv "$VENV"
"$VENV/bin/pip" install --quiet --disable-pip-version-check -r models/train/requirements.txt
PY="$VENV/bin/python"

step "spwi-sim (release)"
cargo build --release --quiet -p spwi-sim
SIM="$CARGO_TARGET_DIR/release/spwi-sim"

# Training seeds: scenario s of seed N exports with seed 10 N + s. The evaluation
# (spwi-sim eval) uses other seeds and checks that no episode seed overlaps.
# The sets see 4 robots an episode; the peer set sees 8, so that a robot has up to 7
# peers (the same episodes: robots 4-7 join the same worker on the same floors).
export_all() { # $1: part name, $2: robots, then extra dataset flags
  local part="$1" robots="$2"; shift 2
  local pids=()
  for s in 1 2 3; do
    "$SIM" dataset --scenario "$s" --layouts "$LAYOUTS" --episodes "$EPISODES" --robots "$robots" --ticks 300 \
      --seed $((SEED * 10 + s)) --out "$DATA/$part-s$s" \
      --track-share "$TRACK_SHARE" --warm-share "$WARM_SHARE" --warm-up-max "$WARM_UP_MAX" "$@" \
      > "$DATA/$part-s$s.log" 2>&1 &
    pids+=($!)
    if [ "${#pids[@]}" -ge 2 ]; then wait "${pids[0]}"; pids=("${pids[@]:1}"); fi
  done
  for p in "${pids[@]}"; do wait "$p"; done
  tail -n 1 "$DATA"/"$part"-s*.log
}

case "$LAYOUTS" in *heldout:*) echo "LAYOUTS=$LAYOUTS: the held-out floors are the evaluation's, never trained on" >&2; exit 2 ;; esac

# The GCN of each kind of graph: the paper's in gcn/, ours in gcn-floor/.
gcn_dir() { case "$1" in appearance) echo "$DATA/gcn" ;; floor_relations) echo "$DATA/gcn-floor" ;; esac; }
needs_floor=""
for set in $SETS; do [ "$set" = paper ] || needs_floor=1; done

if [ -z "${STAGE2_ONLY:-}" ]; then
  rm -rf "$DATA"; mkdir -p "$DATA"
  for from in ${GCN_FROM:-}; do
    kind=$("$PY" -c 'import json,sys; print(json.load(open(sys.argv[1]+"/manifest.json")).get("node_features","appearance"))' "$from")
    step "stage 1: the GCN of $from ($kind graphs)"
    mkdir -p "$(gcn_dir "$kind")"
    cp "$from/gcn.onnx" "$(gcn_dir "$kind")/"
    "$PY" - "$from" "$(gcn_dir "$kind")" <<'PY'
import json, sys
sys.path.insert(0, "models/train")
from set_gcn import graph_of
src, out = sys.argv[1:]
m = json.load(open(f"{src}/manifest.json"))
json.dump(json.load(open(f"{src}/reference.json"))["gcn"], open(f"{out}/gcn_reference.json", "w"))
json.dump({**m["training"]["gcn"], **graph_of({}, m), "from": src}, open(f"{out}/gcn.json", "w"))
PY
  done
  for kind in appearance ${needs_floor:+floor_relations}; do
    [ ! -f "$(gcn_dir "$kind")/gcn.onnx" ] || continue
    step "stage 1 data: spatial graphs ($kind), $EPISODES episodes x 3 scenarios x 4 robots"
    export_all "spatial-$kind" 4 --spatial-every 5 --node-features "$kind"

    step "stage 1: GCN ($kind graphs)"
    (cd models/train && "$PY" train_gcn.py --data "$DATA/spatial-$kind"-s{1,2,3} --out "$(gcn_dir "$kind")" --seed "$SEED")
    rm -rf "$DATA/spatial-$kind"-s*  # the graphs are not needed again
  done

  step "stage 2 data: temporal rows through the exported GCN (agent's Rust code)"
  export_all temporal 4 --gcn "$DATA/gcn/gcn.onnx" --human-features --spatial-every 1000000
  case " $SETS " in *" peer-set "*)
    step "stage 2 data: the same with 8 robots (the peer set's)"
    export_all temporal8 8 --gcn "$DATA/gcn/gcn.onnx" --spatial-every 1000000 ;;
  esac
fi

step "stage 2: temporal models"
for set in $SETS; do
  case "$set" in
    paper)      args=(--window 20 --horizon 20) ;;
    default)    args=(--window 20 --horizon 20 --relations --facing --cnn1d) ;;
    relations)  args=(--window 20 --horizon 20 --relations) ;;
    peer-set)   args=(--window 20 --horizon 20 --relations --peer-set) ;;
    # The study sets: the relations design, other windows and frame counts.
    w10-h10)    args=(--window 10 --horizon 10 --relations) ;;
    w30-h30)    args=(--window 30 --horizon 30 --relations) ;;
    w10-h10-f5) args=(--window 10 --horizon 10 --frames 5 --relations) ;;
    w10-h10-f3) args=(--window 10 --horizon 10 --frames 3 --relations) ;;
    *) echo "unknown model set $set" >&2; exit 2 ;;
  esac
  data=temporal; [ "$set" != peer-set ] || data=temporal8
  gcn="$(gcn_dir floor_relations)"; [ "$set" != paper ] || gcn="$(gcn_dir appearance)"
  (cd models/train && "$PY" train_temporal.py --data "$DATA/$data"-s{1,2,3} --gcn-dir "$gcn" \
    --out "$OUT/$set" --seed "$SEED" "${args[@]}")
  # The study sets' GCN fixes its node count (the daemon pads their graphs): a model
  # from elsewhere may, and the golden tests then cover both ways.
  case "$set" in w*) "$PY" models/train/node_dim.py --fixed 16 "$OUT/$set" ;; esac
done

step "summary"
"$PY" models/train/report.py $(for s in $SETS; do echo "$OUT/$s"; done)
echo "total $((SECONDS - started)) s"
