#!/usr/bin/env bash
# Separate Python 3.11 venv for Judo (PyPI: judo-rai), the CPU planning peer of
# benchmarks/planner_cpu.py. Separate because Judo pins its own mujoco/numpy.
# Usage: benchmarks/judo_env.sh [VENV_DIR]   (default: <repo>/.judo/venv)
# Idempotent: an existing venv with judo importable is reused. Prints the python path.
set -euo pipefail

repo="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
venv="${1:-$repo/.judo/venv}"
py="$venv/bin/python"

if [[ ! -x "$py" ]]; then
  python3.11 -m venv "$venv" 2>/dev/null || python3 -m venv "$venv"
fi
if ! "$py" -c "import judo" >/dev/null 2>&1; then
  "$py" -m pip install --quiet --upgrade pip
  "$py" -m pip install --quiet judo-rai
fi
"$py" -c "import judo" >&2 || { echo "judo import failed" >&2; exit 1; }
echo "$py"
