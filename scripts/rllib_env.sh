#!/usr/bin/env bash
# The second test environment: RLlib with the Gymnasium it pins (ray[rllib] 2.60 pins
# gymnasium==1.2.2, while the test extra resolves the newest Gymnasium). It runs the RLlib
# tests and a Gymnasium-compatibility subset of the suite there.
#
#   bash scripts/rllib_env.sh            # create or update the environment, then run the tests
#   bash scripts/rllib_env.sh --setup    # only create or update it
#
# The environment is a virtual environment in .venv-rllib/ that sees the main environment's
# packages (--system-site-packages: torch, numba, Open3D, Ray are not installed twice) and
# holds only what ray[rllib] adds, Gymnasium 1.2.2 among them, which shadows the main one.
# Ray's version is the one installed in the main environment. A stamp file makes reruns
# skip pip while that version is unchanged. Safe to run again.
set -euo pipefail
cd "$(dirname "$0")/.."
PYTHON="${PYTHON:-python3}"
VENV="${NARUTO_RLLIB_VENV:-.venv-rllib}"
VENV_PYTHON="$VENV/bin/python"

RAY_VERSION="$("$PYTHON" -c 'from importlib.metadata import version; print(version("ray"))')" || {
    echo "Ray is not installed in $PYTHON's environment: run bash scripts/setup.sh first" >&2
    exit 1
}
REQUIREMENT="ray[rllib]==$RAY_VERSION"
STAMP="$VENV/naruto-rllib-requirement"

if [ ! -x "$VENV_PYTHON" ]; then
    # No pip of its own: the main environment's pip installs into it (sys.prefix is the venv).
    "$PYTHON" -m venv --system-site-packages --without-pip "$VENV"
fi
if [ "$(cat "$STAMP" 2>/dev/null)" != "$REQUIREMENT" ] \
    || ! "$VENV_PYTHON" -c "import tree, lz4, ormsgpack" >/dev/null 2>&1; then
    "$VENV_PYTHON" -m pip install --quiet --disable-pip-version-check "$REQUIREMENT"
    echo "$REQUIREMENT" > "$STAMP"
fi
if [ "${1:-}" = "--setup" ]; then
    exit 0
fi

echo "RLlib environment: $REQUIREMENT, $("$VENV_PYTHON" -c \
    'import gymnasium; print("gymnasium", gymnasium.__version__)')"
# The RLlib tests, then the env, vector-env and learning-wrapper tests on the older Gymnasium.
"$VENV_PYTHON" -m pytest -q -p no:cacheprovider \
    tests/rl/test_rllib_example.py tests/rl/test_rllib_env.py tests/rl/test_rllib_explorer.py \
    tests/rl/test_learning_wrappers.py tests/envs/test_registered_envs.py \
    tests/vector/test_vector_env.py -k "not test_vector_env.py or autoreset or delta"
