#!/usr/bin/env bash
# Runs every benchmark in bench/ (each prints one JSON document with its baseline ratio) and keeps the
# JSON in out/bench/NAME.json. A benchmark that fails is reported and the others still run.
set -uo pipefail
cd "$(dirname "$0")/.."
mkdir -p out/bench
status=0
for script in bench/*.py; do
  name=$(basename "$script" .py)
  printf '\n== %s\n' "$name"
  if python "$script" > "out/bench/$name.json.tmp"; then
    mv "out/bench/$name.json.tmp" "out/bench/$name.json"
    cat "out/bench/$name.json"
  else
    rm -f "out/bench/$name.json.tmp"
    echo "bench: $name failed" >&2
    status=1
  fi
done
printf '\nJSON kept in out/bench/\n'
exit $status
