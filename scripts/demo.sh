#!/usr/bin/env bash
# The main job, with the real CLI at every step: analyse and design the pendulum, record a closed-loop
# run of its discrete plant, replay it through the float64 reference and compare.
set -euo pipefail
cd "$(dirname "$0")/.."
out=out/demo
rm -rf "$out"
mkdir -p "$out"
step() { printf '\n== %s\n' "$*"; }

step "1. analyse the plant spec"
gainlink analyze examples/pendulum.toml

step "2. design: DLQR with integral action + Kalman predictor -> $out/gains.json"
gainlink design examples/pendulum.toml --out "$out"
gainlink validate "$out/gains.json"

step "3. record 5 s of closed loop from a 0.1 rad tilt, with sensor noise and a 0.2 m cart reference"
gainlink simulate "$out/gains.json" --steps 500 --x0 0 0 0.1 0 --ref 0.2 --noise 0.0005 --out "$out/samples.csv"

step "4. replay the record through the float64 reference of the control law"
gainlink replay "$out/gains.json" --input "$out/samples.csv" --output "$out/reference.csv" --engine reference

step "5. export the generated C (gains header/source, unrolled step) -> $out/c"
gainlink export "$out/gains.json" --out "$out/c"

step "6. build the host firmware (C11 library, shared object, loop executable) -> $out/fw-host"
gainlink firmware build "$out/gains.json" --target host --out "$out/fw-host"

step "7. replay the same record through the C loop (float32, ctypes, one call per block)"
gainlink replay "$out/gains.json" --input "$out/samples.csv" --output "$out/native.csv" --engine native \
  --compare "$out/reference.csv" --rtol 1e-4

step "8. HIL over CAN: the firmware's CAN node vs the nonlinear pendulum FMU, udp_multicast, lockstep, 10 s"
gainlink hil run pendulum_fmu --artifact "$out/gains.json" --report "$out/hil"
