#!/usr/bin/env bash
# Create/refresh the project-local Python venv with sllurp 3.0.5 ($ROOT/.venv-sllurp3), for
# the interop scripts that drive sllurp 3's library API (scripts/interop/sllurp3_session.py).
# The 3.0.x wheels ship a broken `sllurp` command (sllurp.verb is missing), so only the
# library (sllurp.llrp) is used. Idempotent and quiet; fast when the venv is already in
# place. Usage: scripts/venv-sllurp3.sh
# .gitignore holds `.venv-sllurp3/` (this script does not edit it).
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
VENV="$ROOT/.venv-sllurp3"
PY="$VENV/bin/python"
SLLURP_VERSION="3.0.5"

installed_ok() {
  [ -x "$PY" ] && "$PY" - "$SLLURP_VERSION" <<'PYEOF' 2>/dev/null
import sys, importlib.metadata as md
import sllurp, sllurp.llrp  # noqa: F401
from sllurp.llrp import LLRPReaderClient, LLRPReaderConfig  # noqa: F401
sys.exit(0 if md.version("sllurp") == sys.argv[1] else 1)
PYEOF
}

installed_ok && exit 0

[ -x "$PY" ] || python3 -m venv "$VENV"
"$PY" -m pip install -q --disable-pip-version-check "sllurp==$SLLURP_VERSION"
installed_ok || { echo "venv-sllurp3.sh: sllurp==$SLLURP_VERSION not importable after install" >&2; exit 1; }
