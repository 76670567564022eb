#!/usr/bin/env bash
# Create/refresh the project-local Python venv with the independent MCAP readers
# ($ROOT/.venv-mcap): Foxglove's `mcap` 1.6.0 with `mcap-ros2-support` 0.6.0 (ROS 2 CDR
# decoding from the schemas in the file), and `rosbags` 0.11.9 (a ROS 2 bag reader of its
# own, no ROS install), for the checker scripts/interop/mcap_check.py that the MCAP tests run (tests/mcap_out.rs);
# `websockets` 17.4 for scripts/interop/foxglove_client.py, the Foxglove WebSocket client of
# tests/foxglove_live.rs.
# Idempotent and quiet; fast when the venv is already in place. Usage: scripts/venv-mcap.sh
# .gitignore holds `.venv-mcap/` (this script does not edit it).
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
VENV="$ROOT/.venv-mcap"
PY="$VENV/bin/python"
PINS=("mcap==1.6.0" "mcap-ros2-support==0.6.0" "rosbags==0.11.9" "websockets==17.4")

installed_ok() {
  [ -x "$PY" ] && "$PY" - "${PINS[@]}" <<'PYEOF' 2>/dev/null
import sys, importlib.metadata as md
import mcap.reader, mcap_ros2.decoder, rosbags.rosbag2, rosbags.highlevel, websockets  # noqa: F401
for pin in sys.argv[1:]:
    name, version = pin.split("==")
    if md.version(name) != version:
        sys.exit(1)
PYEOF
}

installed_ok && exit 0

[ -x "$PY" ] || python3 -m venv "$VENV"
"$PY" -m pip install -q --disable-pip-version-check "${PINS[@]}"
installed_ok || { echo "venv-mcap.sh: ${PINS[*]} not importable after install" >&2; exit 1; }
