#!/usr/bin/env bash
# Installs everything gainlink needs on a fresh Debian machine: the apt packages that are missing
# (ARM toolchain, QEMU for Cortex-M PIL and for the vcan VM, busybox for its initramfs, rt-tests'
# cyclictest for the real-time benchmark's machine floor, clang for the libFuzzer harnesses, Ninja and ccache
# for quicker firmware builds, SLEEF's libsleef-dev for the built-in plants' sin and cos) and a virtualenv in
# .venv with the project installed in editable mode with its test and docs extras.
set -euo pipefail
cd "$(dirname "$0")/.."

APT_PACKAGES=(
  build-essential cmake
  gcc-arm-none-eabi libnewlib-arm-none-eabi binutils-arm-none-eabi
  qemu-system-arm qemu-system-x86 busybox-static cpio
  libmsgpack-dev rt-tests clang ninja-build ccache libsleef-dev
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
  # Without pip: installing pip into the venv (ensurepip) took 8 of the set-up's 33 s, and uv installs the rest.
  "$PYTHON" -m venv --without-pip .venv
fi
echo "setup: installing gainlink into .venv"
# uv resolves and installs the same pinned ranges as pip in about half the time; pip is the fallback when uv cannot be
# had or fails. uv does not compile bytecode here (compiling all of site-packages took 55 CPU-s, most of it never
# imported): scripts/warm_bytecode.py imports what gainlink and its tests use, once, which writes theirs (28 CPU-s).
# MAVProxy for the MAVLink tests comes without its declared GUI/map dependencies (opencv, vtk, ...: hundreds of MB):
# its core and parameter module need only pymavlink, numpy, pyserial and defusedxml (the test extra).
install_with() {
  "$@" -e '.[test,docs]' && "$@" --no-deps 'MAVProxy>=1.8.75,<1.9'
}
# uv goes into the venv with the machine's own pip (pip >= 22.3 has --python), else with the venv's (made if need be).
install_uv() {
  "$PYTHON" -m pip --python .venv/bin/python install -q 'uv==0.13.9' >/dev/null 2>&1 && return
  .venv/bin/python -m pip --version >/dev/null 2>&1 || .venv/bin/python -m ensurepip >/dev/null 2>&1
  .venv/bin/python -m pip install -q 'uv==0.13.9' >/dev/null 2>&1
}
if install_uv && install_with .venv/bin/uv pip install -q --python .venv/bin/python; then
  env -u PYTHONDONTWRITEBYTECODE .venv/bin/python scripts/warm_bytecode.py
else
  echo "setup: uv unavailable or failed; installing with pip"
  .venv/bin/python -m pip --version >/dev/null 2>&1 || .venv/bin/python -m ensurepip >/dev/null
  .venv/bin/python -m pip install -q --upgrade pip >/dev/null
  install_with .venv/bin/python -m pip install -q  # pip compiles the bytecode itself
fi
