#!/usr/bin/env bash
# Sets up, then runs the NARUTO agent on the default scene (about 3 minutes on 2 cores);
# outputs land in outputs/demo. Flags pass through: --policy, --scene, --max-episode-steps, --seed, --output-dir.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
"${PYTHON:-python3}" -m naruto_agent.demo "$@"
