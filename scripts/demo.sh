#!/usr/bin/env bash
# The main job, step by step with the real CLI: design the pendulum, export C, replay.
set -euo pipefail
cd "$(dirname "$0")/.."
out=out/demo
mkdir -p "$out"
gainlink analyze examples/pendulum.toml
gainlink design examples/pendulum.toml --out "$out"
