#!/usr/bin/env bash
# Create .venv and install suture-bt (editable, with test tools) with the pinned CPU torch.
set -euo pipefail
cd "$(dirname "$0")/.."
PY=${PYTHON:-python3.11}
command -v "$PY" >/dev/null 2>&1 || PY=python3
[ -x .venv/bin/python ] || "$PY" -m venv .venv
.venv/bin/python -m pip install -q --upgrade pip >/dev/null 2>&1 || true
.venv/bin/python -m pip install -q -c constraints.txt -e '.[dev]' 2>&1 | grep -v '^WARNING: Location' || true
.venv/bin/python -c "import suture_bt, torch, pybullet" 2>/dev/null || { echo "setup failed: suture_bt, torch or pybullet does not import" >&2; exit 1; }
