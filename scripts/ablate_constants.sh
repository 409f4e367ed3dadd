#!/usr/bin/env bash
# The paired, family-by-family ablation (`cf-estimator bench ablate`) of constants of the
# compiled step: each NAME=VALUE sets one `#define` of cf_estimator/core/c/cf_core.c in a
# scratch worktree of HEAD, rebuilds the core there and scores it against the base scores of
# this checkout (docs/decisions/0013-fewer-parameters.md, "Constants checked the same way").
# The Python reference is not changed: bench ablate runs the compiled core.
#
#   bash scripts/ablate_constants.sh BASE.json MAG_TURN_FRACTION=0.0 ACCEL_SPIKE_SIGMAS=1e9
#
# BASE.json: an earlier `cf-estimator bench ablate --json` output of this checkout (its "base"
# scores); each variant's table goes to stdout and its scores to ablate_NAME.json here.
set -euo pipefail
if [ $# -lt 2 ]; then
    echo "usage: $0 BASE.json NAME=VALUE [NAME=VALUE ...]" >&2
    exit 2
fi
base=$(realpath "$1")
shift
repo=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
out=$(pwd)
data=$(realpath "$repo/../shared/data")
scratch=$(mktemp -d)
trap 'git -C "$repo" worktree remove --force "$scratch/tree" >/dev/null 2>&1 || true; rm -rf "$scratch"' EXIT
git -C "$repo" worktree add -q --detach "$scratch/tree" HEAD
core="$scratch/tree/cf_estimator/core/c/cf_core.c"
for spec in "$@"; do
    name=${spec%%=*}
    value=${spec#*=}
    git -C "$scratch/tree" checkout -q -- cf_estimator/core/c/cf_core.c
    if ! grep -q "^#define $name " "$core"; then
        echo "$0: cf_core.c has no #define $name" >&2
        exit 2
    fi
    sed -i "s/^#define $name .*/#define $name $value/" "$core"
    (cd "$scratch/tree" && python3 setup.py -q build_ext --inplace >/dev/null 2>&1)
    (cd "$scratch/tree" && PYTHONPATH="$scratch/tree" python3 -m cf_estimator.cli.main bench ablate \
        --data "$data" --base-scores "$base" --variant "$name=$value:" \
        --json "$out/ablate_$name.json" --overwrite)
done
