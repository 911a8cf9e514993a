#!/usr/bin/env bash
# Bakes a scene on a Slurm cluster: a job array of N shards, then a merge job that runs when
# all of them succeeded. Prints the merge job's id.
#
#   examples/slurm/submit.sh SCENE CELLS N OUTPUT [more bake flags…]
#
# SCENE, CELLS and OUTPUT must be on a file system every node sees. Shards go to
# OUTPUT.shards/. UMBRASWEEP names the binary (default: umbrasweep on PATH); extra sbatch
# options (partition, account, time) go in SBATCH_ARGS.
set -euo pipefail
scene=$(realpath "${1:?usage: submit.sh SCENE CELLS N OUTPUT [bake flags…]}")
cells=$(realpath "${2:?cells file}")
n=${3:?number of shards}
output=$(realpath -m "${4:?output .json or .pvs}")
shift 4
here=$(dirname "$(realpath "$0")")
bin=$(command -v "${UMBRASWEEP:-umbrasweep}")
out_dir="$output.shards"
mkdir -p "$out_dir/log"
export UMBRASWEEP="$bin" SCENE="$scene" CELLS="$cells" OUT_DIR="$out_dir" OUTPUT="$output"
export BAKE_ARGS="$*"
# shellcheck disable=SC2086
array=$(sbatch --parsable ${SBATCH_ARGS:-} --array="0-$((n - 1))" \
    --output="$out_dir/log/bake-%a.out" --export=ALL "$here/bake-array.sbatch")
# shellcheck disable=SC2086
sbatch --parsable ${SBATCH_ARGS:-} --dependency="afterok:${array%%;*}" \
    --output="$out_dir/log/merge.out" --export=ALL "$here/merge.sbatch"
