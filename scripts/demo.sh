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

step "7. replay the same record through the C loop (float32, ctypes, one call per block), checked one step at a time"
gainlink replay "$out/gains.json" --input "$out/samples.csv" --output "$out/native.csv" --engine native \
  --compare "$out/reference.csv"

step "8. HIL over CAN: the firmware's CAN node vs the nonlinear pendulum FMU, udp_multicast, lockstep, 10 s,"
printf '   beside its float64 twin (reference law + a second FMU instance, same noise, reference, disturbance)\n'
gainlink hil run pendulum_fmu --artifact "$out/gains.json" --report "$out/hil"
printf '   twin comparison: %s (report.json "twin"), plot %s\n' "$out/hil/report.json" "$out/hil/twin.png"

step "9. build the Cortex-M4F image for mps2-an386 (.elf .bin .hex .map, size report) -> $out/fw-m4"
gainlink firmware build "$out/gains.json" --target cortex-m4 --board mps2-an386 --out "$out/fw-m4"

step "10. HIL with the image itself: MAVLink on its emulated UART (QEMU), vs the pendulum FMU, lockstep, 3 s"
gainlink hil run pendulum_qemu_mavlink --artifact "$out/gains.json" --report "$out/hil-uart"

step "11. upload retuned gains to the running image over its UART: verified, committed, persisted in its flash"
sed -e 's/^Q_diag = \[10.0, 1.0, 100.0, 1.0\]/Q_diag = [40.0, 1.0, 300.0, 2.0]/' examples/pendulum.toml \
  > "$out/pendulum_retuned.toml"
gainlink design "$out/pendulum_retuned.toml" --out "$out/retuned" > /dev/null
image_pid=""
stop_image() { [ -n "$image_pid" ] && kill "$image_pid" 2>/dev/null && wait "$image_pid" 2>/dev/null; image_pid=""; }
trap stop_image EXIT
serve_image() {  # the image in QEMU with the demo's flash folder; waits for its ready line
  gainlink firmware run "$out/gains.json" --target cortex-m4 --mavlink tcp:127.0.0.1:5761 \
    --flash-dir "$out/flash" > "$out/image.log" 2>&1 &
  image_pid=$!
  for _ in $(seq 100); do grep -q "ready mavlink" "$out/image.log" && break; sleep 0.2; done
  head -1 "$out/image.log"
}
serve_image
gainlink mavlink upload "$out/retuned/gains.json" --connect tcp:127.0.0.1:5761 --persist
stop_image
printf '\n   ... the image restarted (power cycle): the gains come back from its flash\n'
serve_image
gainlink mavlink upload "$out/retuned/gains.json" --connect tcp:127.0.0.1:5761 --dry-run
stop_image
