#!/usr/bin/env bash
# Sets up, then runs the whole test suite (slow tests included), then the RLlib tests and a
# Gymnasium-compatibility subset in the second environment of scripts/rllib_env.sh (RLlib
# pins an older Gymnasium than the test extra resolves). NARUTO_RLLIB_ENV=0 skips that part.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
status=0
# One worker per core of this machine; a test module stays on one worker (its fixtures, such as a
# docs page's REPL session, are module-scoped).
"${PYTHON:-python3}" -m pytest -n auto --dist loadscope "$@" || status=$?
if [ "${NARUTO_RLLIB_ENV:-1}" != "0" ]; then
    bash scripts/rllib_env.sh || status=$?
fi
exit "$status"
