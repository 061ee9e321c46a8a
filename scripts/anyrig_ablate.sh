#!/usr/bin/env bash
# Ablation rows of the creatures model card (issue 15): the full anyrig-small recipe and the same run
# without TreePE, without RestPE, without rig augmentation and without the hop-distance attention bias
# (AnyTop's topology bias; TreePE alone then carries the tree), each trained from scratch for the same
# short schedule (seed 0, same build), then evaluated on train and held-out rigs.
#   bash scripts/anyrig_ablate.sh [STEPS] [RUNS_DIR] [ROW ...]   (default 2000 steps, runs/ablate, all rows)
# Resumable: a finished run is skipped, a stopped one continues from its newest checkpoint.
set -euo pipefail
steps=${1:-2000}
runs=${2:-runs/ablate}
shift $(( $# < 2 ? $# : 2 ))
rows=("$@")
[ ${#rows[@]} -gt 0 ] || rows=(full no-tree-pe no-rest-pe no-aug no-hop-bias)
data=${KINEMA_ABLATE_DATA:-cache/quat20}
mkdir -p "$runs"
declare -A flags=([full]="" [no-tree-pe]="--no-tree-pe" [no-rest-pe]="--no-rest-pe" [no-aug]="--variants 0"
                  [no-hop-bias]="--no-hop-bias")
for row in "${rows[@]}"; do
    [ -n "${flags[$row]+set}" ] || { echo "unknown row $row (rows: ${!flags[*]})" >&2; exit 2; }
    out="$runs/$row"
    resume=$([ -d "$out" ] && echo --resume || true)
    # shellcheck disable=SC2086
    kinema train-anyrig --config anyrig-small --data "$data" --out "$out" --steps "$steps" --seed 0 \
        --log-every 100 --ckpt-every 500 --threads 1 ${flags[$row]} $resume
    [ -f "$runs/$row.json" ] || kinema evaluate-anyrig --model "$out" --data "$data" --splits train val test \
        --clips 2 --steps 20 --threads 1 --out "$runs/$row.json"
done
