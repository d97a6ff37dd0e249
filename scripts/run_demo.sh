#!/usr/bin/env bash
# Sets up, then runs the main job on the default scene; outputs land in outputs/demo.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
"${PYTHON:-python3}" -m naruto_gym.demo "$@"
