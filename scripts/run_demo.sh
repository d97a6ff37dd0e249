#!/usr/bin/env bash
# Sets up what the demo needs (the system library Open3D loads, the CPU torch wheel, the
# package with its viewer extra: no test tools), then runs the NARUTO agent on the default
# scene (one to two minutes on 2 cores); outputs land in outputs/demo. Flags pass through
# (naruto-demo --help lists them). torch comes from PyTorch's CPU wheel index,
# https://download.pytorch.org/whl/cpu (TORCH_INDEX_URL overrides it: scripts/setup.sh).
# Flags pass through: --policy, --scene, --max-episode-steps, --seed, --output-dir.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh viewer
"${PYTHON:-python3}" -m naruto_agent.demo "$@"
