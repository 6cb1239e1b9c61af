#!/bin/sh
# Instruction counts of the step's kernels on thigh13 under callgrind, compared with the
# reference kept next to this script (callgrind-reference.txt: "kernel instructions" lines).
#   callgrind.sh [--check | --update] [BENCH] [RESOLUTION]
# prints the default solver's instructions per iteration against Verlet's, then each kernel's
# count, the reference's and the change; --check exits 1 when a kernel moved by more than
# FIBREMSS_CALLGRIND_TOLERANCE percent (default 10), --update rewrites the reference. Exits 77
# (ctest: skipped) without valgrind. Counts hold for a plain Release float build; sanitizers,
# the double build or another compiler give other counts.
set -eu
here=$(cd "$(dirname "$0")" && pwd)
mode=report
case "${1:-}" in --check | --update) mode=${1#--}; shift ;; esac
bench=${1:-$here/../../build/bin/fibremss_bench}
resolution=${2:-20}
reference=$here/callgrind-reference.txt
tolerance=${FIBREMSS_CALLGRIND_TOLERANCE:-10}
# The spring kernel is chosen by the CPU (SSE2, or AVX2 where present): counted on SSE2 unless
# FIBREMSS_SPRING_KERNEL names another, so that the reference holds on any x86-64 machine.
FIBREMSS_SPRING_KERNEL=${FIBREMSS_SPRING_KERNEL:-sse2}
export FIBREMSS_SPRING_KERNEL

if ! command -v valgrind >/dev/null 2>&1; then
  echo "valgrind not found: callgrind counts not measured"
  exit 77
fi
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
valgrind --tool=callgrind --instr-atstart=no --callgrind-out-file="$work/cg.%p" \
  "$bench" --callgrind-kernels "$resolution" >"$work/log" 2>&1 || {
  cat "$work/log"
  exit 1
}
# One dump per kernel: its name in the trigger line, its instructions in the totals line.
for dump in "$work"/cg.*.*; do
  awk '/^desc: Trigger: Client Request: / { name = $5 }
       /^(totals|summary): / { count = $2 }
       END { if (name != "") print name, count }' "$dump"
done | sort >"$work/now"
# The two whole steps (10 iterations each): the default solver's cost per iteration against
# Verlet's.
awk '$1 == "step-10-iterations" { verlet = $2 } $1 == "default-solver-step-10-iterations" { solver = $2 }
     END { if (verlet > 0 && solver > 0)
             printf "per iteration: default solver %.1f M, Verlet %.1f M instructions, %.3fx\n",
                    solver / 1e7, verlet / 1e7, solver / verlet }' "$work/now"

if [ "$mode" = update ]; then
  { echo "# callgrind instructions per kernel, thigh13 resolution $resolution, one thread"
    echo "# (comparisons/bench/callgrind.sh --update; plain Release float build)"
    cat "$work/now"; } >"$reference"
  cat "$reference"
  exit 0
fi
[ -f "$reference" ] || { echo "no reference: $reference"; exit 1; }
grep -v '^#' "$reference" | sort >"$work/ref"
join -a 1 -a 2 -e missing -o 0,1.2,2.2 "$work/ref" "$work/now" | awk -v tol="$tolerance" -v mode="$mode" '
  BEGIN { printf "%-22s %14s %14s %9s\n", "kernel", "reference", "now", "change"; bad = 0 }
  {
    if ($2 == "missing" || $3 == "missing") { printf "%-22s %14s %14s %9s\n", $1, $2, $3, "-"; bad = 1; next }
    change = 100 * ($3 - $2) / $2
    flag = (change > tol || change < -tol) ? "  <-- beyond " tol "%" : ""
    if (flag != "") bad = 1
    printf "%-22s %14d %14d %+8.1f%%%s\n", $1, $2, $3, change, flag
  }
  END { exit (mode == "check" && bad) ? 1 : 0 }'
