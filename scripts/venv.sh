#!/usr/bin/env bash
# Create/refresh the project-local Python venv used by the interop scripts
# ($ROOT/.venv) with sllurp pinned to 2.0.1 (the 3.0.x wheels ship a broken
# `sllurp` command: sllurp.verb is missing). Idempotent and quiet; fast when
# the venv is already in place. Usage: scripts/venv.sh
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
VENV="$ROOT/.venv"
PY="$VENV/bin/python"
SLLURP_VERSION="2.0.1"

# .gitignore must hold .venv/ and /target
touch "$ROOT/.gitignore"
for pat in ".venv/" "/target"; do
  grep -qxF "$pat" "$ROOT/.gitignore" || printf '%s\n' "$pat" >> "$ROOT/.gitignore"
done

installed_ok() {
  [ -x "$PY" ] && "$PY" - "$SLLURP_VERSION" <<'PYEOF' 2>/dev/null
import sys, importlib.metadata as md
import sllurp, sllurp.llrp  # noqa: F401
sys.exit(0 if md.version("sllurp") == sys.argv[1] else 1)
PYEOF
}

installed_ok && exit 0

[ -x "$PY" ] || python3 -m venv "$VENV"
"$PY" -m pip install -q "sllurp==$SLLURP_VERSION"
installed_ok || { echo "venv.sh: sllurp==$SLLURP_VERSION not importable after install" >&2; exit 1; }
