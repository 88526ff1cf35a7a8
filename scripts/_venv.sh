# Shared set-up for scripts/*: create a venv at the repository root and install the project.
# Sourced, not run. Installs the exact versions of requirements.lock (Python 3.11, Linux) and
# re-installs when pyproject.toml or the lock changed since the last install.
# MPF_LATEST=1 (scripts/test --latest) uses .venv-latest instead, without the lock: the newest
# versions pyproject's bounds allow, so drift shows up here before it reaches users.
# Refresh the lock: python -m pip install uv && uv pip compile pyproject.toml --extra dev
#   --python-version 3.11 --python-platform linux -o requirements.lock
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
PY="${PYTHON:-python3.11}"
command -v "$PY" >/dev/null 2>&1 || PY=python3
if [ "${MPF_LATEST:-0}" = 1 ]; then
  VENV="$ROOT/.venv-latest"
else
  VENV="$ROOT/.venv"
fi
if [ ! -x "$VENV/bin/python" ]; then
  echo "[setup] creating $VENV with $PY" >&2
  "$PY" -m venv "$VENV"
fi
STAMP="$VENV/.mpf-installed"
if [ "${MPF_LATEST:-0}" = 1 ]; then
  echo "[setup] installing the newest versions pyproject.toml allows into .venv-latest" >&2
  "$VENV/bin/python" -m pip install --quiet --upgrade pip >&2
  "$VENV/bin/python" -m pip install --quiet --upgrade --upgrade-strategy eager -e "$ROOT[dev]" >&2
  "$VENV/bin/python" - >&2 <<'PYEOF'
from importlib.metadata import version
print("[setup] latest:", ", ".join(f"{p} {version(p)}" for p in
      ("numpy", "scipy", "pymavlink", "jsbsim", "matplotlib", "pymap3d", "pyyaml", "pytest")))
PYEOF
elif [ ! -f "$STAMP" ] || [ "$ROOT/pyproject.toml" -nt "$STAMP" ] || [ "$ROOT/requirements.lock" -nt "$STAMP" ]; then
  echo "[setup] installing mpf-mavlink with the versions of requirements.lock into .venv" >&2
  "$VENV/bin/python" -m pip install --quiet --upgrade pip >&2
  "$VENV/bin/python" -m pip install --quiet -c "$ROOT/requirements.lock" -e "$ROOT[dev]" >&2
  touch "$STAMP"
fi
export PATH="$VENV/bin:$PATH"
export JSBSIM_DEBUG=0
