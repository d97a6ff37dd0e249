#!/usr/bin/env bash
# Installs what naruto-gym needs on a fresh Debian/Ubuntu machine: the system library Open3D
# loads, the CPU torch wheel, then the package with the extras named as the argument
# (default: test). Safe to run again.
#
#   bash scripts/setup.sh            # the package with its test extra (what CI runs)
#   bash scripts/setup.sh viewer     # the package with the demo's viewer extra only
#
# With the test extra it also installs what the 3D page's headless-browser test drives:
# Debian's chromium (apt-get) and playwright (PyPI); the test starts /usr/bin/chromium
# through playwright, so `playwright install` (a download of its own browsers) is not needed.
#
# torch is the CPU build (PyPI's Linux wheel brings several GB of CUDA libraries): from pip's
# configured sources when they already serve it (a wheel folder, a mirror; a dry-run resolve
# checks, fetching no wheel), else from PyTorch's CPU wheel index, the same as
#   pip install torch --index-url https://download.pytorch.org/whl/cpu
# TORCH_INDEX_URL=URL takes torch from URL; TORCH_INDEX_URL= (empty) from pip's configured
# sources, unchecked.
#
#   bash scripts/setup.sh --torch-index   # say where torch would come from, install nothing
set -euo pipefail
cd "$(dirname "$0")/.."
PYTHON="${PYTHON:-python3}"
TORCH_VERSION="2.13.0"
CPU_TORCH_INDEX_URL="https://download.pytorch.org/whl/cpu"
PIP=("$PYTHON" -m pip install --quiet --disable-pip-version-check)

# torch_index: the pip arguments that choose torch's index, one a line (none: pip's
# configured sources).
torch_index() {
    if [ -n "${TORCH_INDEX_URL+set}" ]; then
        if [ -n "$TORCH_INDEX_URL" ]; then
            printf '%s\n' --index-url "$TORCH_INDEX_URL"
        fi
        return 0
    fi
    if "${PIP[@]}" --dry-run --no-deps --ignore-installed --retries 1 --timeout 30 \
            --report - "torch==$TORCH_VERSION" 2>/dev/null \
        | "$PYTHON" -c 'import json, sys
sys.exit(not any("+cpu" in item["metadata"]["version"] for item in json.load(sys.stdin)["install"]))' \
            2>/dev/null; then
        return 0
    fi
    printf '%s\n' --index-url "$CPU_TORCH_INDEX_URL"
}

if [ "${1:-}" = "--torch-index" ]; then
    mapfile -t index < <(torch_index)
    configured="pip's configured sources"
    echo "torch==$TORCH_VERSION from: ${index[1]:-$configured}"
    exit 0
fi
EXTRAS="${1:-test}"

# apt_install PACKAGE...: install system packages, as root or through sudo.
apt_install() {
    if [ "$(id -u)" -eq 0 ]; then
        apt-get update -qq && apt-get install -y -qq "$@" >/dev/null
    elif command -v sudo >/dev/null; then
        sudo apt-get update -qq && sudo apt-get install -y -qq "$@" >/dev/null
    else
        echo "install $* with your system's package manager, then run this again" >&2
        exit 1
    fi
}

if ! ldconfig -p 2>/dev/null | grep -q "libusb-1.0.so.0"; then
    apt_install libusb-1.0-0  # Open3D loads it
fi

# torch first, pinned, so that the package's torch range never pulls a CUDA build.
if ! "$PYTHON" -c "import torch, sys; sys.exit(torch.__version__.split('+')[0] != '$TORCH_VERSION')" \
        2>/dev/null; then
    mapfile -t index < <(torch_index)
    "${PIP[@]}" "torch==$TORCH_VERSION" "${index[@]}"
fi
"${PIP[@]}" -e ".[$EXTRAS]"

if [[ ",$EXTRAS," == *",test,"* ]]; then
    if [ ! -x /usr/bin/chromium ]; then
        apt_install chromium
    fi
    "${PIP[@]}" playwright
fi
