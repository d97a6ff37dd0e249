#!/usr/bin/env bash
# Installs what naruto-gym needs on a fresh machine: the system library Open3D loads, the CPU
# torch wheel, then the package with its test extras. Safe to run again.
set -euo pipefail
cd "$(dirname "$0")/.."
PYTHON="${PYTHON:-python3}"

if ! ldconfig -p 2>/dev/null | grep -q "libusb-1.0.so.0"; then
    if [ "$(id -u)" -eq 0 ]; then
        apt-get update -qq && apt-get install -y -qq libusb-1.0-0 >/dev/null
    elif command -v sudo >/dev/null; then
        sudo apt-get update -qq && sudo apt-get install -y -qq libusb-1.0-0 >/dev/null
    else
        echo "Open3D needs libusb-1.0-0: install it with your system's package manager" >&2
        exit 1
    fi
fi

# torch first, pinned, so that the package's torch range never pulls a multi-GB CUDA build.
"$PYTHON" -m pip install --quiet --disable-pip-version-check "torch==2.13.0"
"$PYTHON" -m pip install --quiet --disable-pip-version-check -e ".[test]"
