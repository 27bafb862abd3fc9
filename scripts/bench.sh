#!/usr/bin/env bash
# Runs benchmarks of bench/ (each prints one JSON document with its baseline ratio), keeps the JSON in
# out/bench/NAME.json, then records the ones that succeeded as the docs' figures
# (scripts/doc_figures.py --record: bench/results/NAME.json and the marked blocks of the README and docs/).
#
#   scripts/bench.sh            the quick benchmarks: every bench/*.py but the long ones and _*.py (minutes)
#   scripts/bench.sh NAME ...   these (bench/NAME.py), e.g. `fuzz` or `soak` (an hour each)
#
# A benchmark that fails is reported and the others still run.
set -uo pipefail
cd "$(dirname "$0")/.."
LONG=(fuzz soak)  # their own make targets: bench-fuzz, bench-soak

names=("$@")
if ((${#names[@]} == 0)); then
  for script in bench/[!_]*.py; do  # bench/_*.py: modules they share
    name=$(basename "$script" .py)
    [[ " ${LONG[*]} " == *" $name "* ]] || names+=("$name")
  done
fi
mkdir -p out/bench
status=0
done_ok=()
for name in "${names[@]}"; do
  printf '\n== %s\n' "$name"
  if python "bench/$name.py" > "out/bench/$name.json.tmp"; then
    mv "out/bench/$name.json.tmp" "out/bench/$name.json"
    cat "out/bench/$name.json"
    done_ok+=("$name")
  else
    rm -f "out/bench/$name.json.tmp"
    echo "bench: $name failed" >&2
    status=1
  fi
done
printf '\nJSON kept in out/bench/\n'
if ((${#done_ok[@]})); then
  python scripts/doc_figures.py --record "${done_ok[@]}" || status=1
fi
exit $status
