#!/usr/bin/env bash
# Create/refresh the benchmark venv ($ROOT/.venv-bench, the one scripts/bench-sim uses) with
# llrpkit pinned to 0.3.0, whose `llrpkit emulate` reader emulator the inventory client's
# test runs against (tests/cli_inventory.rs, LLRP_LLRPKIT), with its `mqtt` extra (aiomqtt
# pinned) for `llrpkit inventory --mqtt-broker`, the peer of scripts/bench-mqtt. Idempotent and
# quiet; fast when the venv is already in place. Prints nothing on success.
# Usage: scripts/venv-llrpkit.sh
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
VENV="$ROOT/.venv-bench"
PY="$VENV/bin/python"
LLRPKIT_VERSION="0.3.0"
AIOMQTT_VERSION="2.5.1"

# .gitignore must hold the benchmark venv.
touch "$ROOT/.gitignore"
grep -qxF ".venv-bench/" "$ROOT/.gitignore" || printf '%s\n' ".venv-bench/" >>"$ROOT/.gitignore"

installed_ok() {
  [ -x "$PY" ] && [ -x "$VENV/bin/llrpkit" ] && "$PY" - "$LLRPKIT_VERSION" "$AIOMQTT_VERSION" <<'PYEOF' 2>/dev/null
import sys, importlib.metadata as md
import llrpkit.emulator  # noqa: F401
import llrpkit.mqtt  # noqa: F401
sys.exit(0 if md.version("llrpkit") == sys.argv[1] and md.version("aiomqtt") == sys.argv[2] else 1)
PYEOF
}

installed_ok && exit 0

[ -x "$PY" ] || python3 -m venv "$VENV"
"$PY" -m pip install -q "llrpkit[mqtt]==$LLRPKIT_VERSION" "aiomqtt==$AIOMQTT_VERSION"
installed_ok || { echo "venv-llrpkit.sh: llrpkit[mqtt]==$LLRPKIT_VERSION not importable after install" >&2; exit 1; }
