#!/usr/bin/env bash
# Corpus time benchmark (issue 11): every program of LinuxCNC's trajectory-planner corpus
# (../shared/corpus/linuxcnc-tp/, relative to the repository) that plans, timed in trapezoid
# and in jerk-limited ("s-curve") mode on MACHINE at a 1 ms cycle with the travel widened,
# with the ratio, the reference time T_ref and T_lb; then the geometric mean of the ratio,
# the 10 worst programs and those above 1.5x not within 1.1x of T_ref.
#
#   tools/corpus-times.sh [MACHINE] [--check]   # default dictionaries/machines/demo-xyz.toml
#
# --check also checks every jerk-limited plan at that period as the acceptance asks (each
# axis's velocity, acceleration and jerk within 1 %, the distance from the path within the
# tolerance, stops and the end on the path) and exits 1 if one fails.
#
# The table goes to stdout, progress to stderr. The work is examples/corpus_times.rs (release
# build); the bounds are canmotion::planner::bounds. Says so and exits 0 without the corpus.
set -euo pipefail
root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
check=()
args=()
for a in "$@"; do
    if [[ "$a" == --check ]]; then check=(--check); else args+=("$a"); fi
done
machine=${args[0]:-$root/dictionaries/machines/demo-xyz.toml}
[[ -f "$machine" ]] || {
    echo "corpus-times: no machine file '$machine'" >&2
    exit 2
}
machine=$(cd "$(dirname "$machine")" && pwd)/$(basename "$machine")
cd "$root"
exec cargo run --quiet --release --example corpus_times -- "$machine" "${check[@]}"
