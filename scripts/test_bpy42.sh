#!/usr/bin/env bash
# The Blender tests on the oldest Blender the extension supports: the bpy 4.2 LTS module (Python
# 3.11), in a second environment .venv-bpy42 made from requirements-bpy42.txt. The core's tests do not
# depend on Blender and run in .venv only. This environment also makes the shipped sample scenes:
#     .venv-bpy42/bin/python sample_scenes/make_scenes.py
set -euo pipefail
cd "$(dirname "$0")/.."
PY=${PYTHON:-python3.11}
command -v "$PY" >/dev/null 2>&1 || PY=python3
if ! "$PY" -c 'import sys; sys.exit(sys.version_info[:2] != (3, 11))'; then
    echo "test_bpy42: Python 3.11 is required (bpy 4.2 is built for it); found $("$PY" --version 2>&1)" >&2
    exit 1
fi
[ -x .venv-bpy42/bin/python ] || "$PY" -m venv .venv-bpy42
stamp=.venv-bpy42/.requirements.sha256
want=$(sha256sum requirements-bpy42.txt | cut -d' ' -f1)
if [ "$(cat "$stamp" 2>/dev/null)" != "$want" ]; then
    .venv-bpy42/bin/python -m pip install --quiet --upgrade pip
    .venv-bpy42/bin/python -m pip install --quiet -r requirements-bpy42.txt
    echo "$want" > "$stamp"
fi
exec .venv-bpy42/bin/python -m pytest -p no:cacheprovider tests/blender "$@"
