#!/usr/bin/env bash
# Installs everything gainlink needs on a fresh Debian machine: the apt packages that are missing
# (ARM toolchain, QEMU for Cortex-M PIL and for the vcan VM, busybox for its initramfs, rt-tests'
# cyclictest for the real-time benchmark's machine floor, clang for the libFuzzer harnesses, Ninja and ccache
# for quicker firmware builds) and a virtualenv in .venv with the project installed in editable mode with its test extras.
set -euo pipefail
cd "$(dirname "$0")/.."

APT_PACKAGES=(
  build-essential cmake
  gcc-arm-none-eabi libnewlib-arm-none-eabi binutils-arm-none-eabi
  qemu-system-arm qemu-system-x86 busybox-static cpio
  libmsgpack-dev rt-tests clang ninja-build ccache
)
missing=()
for pkg in "${APT_PACKAGES[@]}"; do
  dpkg-query -W -f='${Status}' "$pkg" 2>/dev/null | grep -q "install ok installed" || missing+=("$pkg")
done
if ((${#missing[@]})); then
  sudo=""
  [ "$(id -u)" = 0 ] || sudo="sudo"
  echo "setup: installing apt packages: ${missing[*]}"
  $sudo apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq "${missing[@]}" >/dev/null
fi

PYTHON=${PYTHON:-python3}
if [ ! -x .venv/bin/python ]; then
  echo "setup: creating .venv"
  "$PYTHON" -m venv .venv
fi
echo "setup: installing gainlink into .venv"
# uv resolves and installs the same pinned ranges as pip in a fraction of the time (about 15 s instead of 50 s
# on a fresh 2-core machine; it is part of every fresh `make test`); pip remains the fallback.
if .venv/bin/python -m pip install -q 'uv==0.13.9' >/dev/null 2>&1; then
  install=(.venv/bin/uv pip install -q --compile-bytecode --python .venv/bin/python)
else
  .venv/bin/python -m pip install -q --upgrade pip >/dev/null
  install=(.venv/bin/python -m pip install -q)
fi
"${install[@]}" -e '.[test]'
# MAVProxy for the MAVLink tests, without its declared GUI/map dependencies (opencv, vtk, ...: hundreds of MB);
# its core and parameter module need only pymavlink, numpy, pyserial and defusedxml (the test extra).
"${install[@]}" --no-deps 'MAVProxy>=1.8.75,<1.9'
