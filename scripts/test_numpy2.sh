#!/usr/bin/env bash
# The core's tests at the numpy the newest Blender ships (requirements-numpy2.txt says which and why):
# a second environment in .venv-numpy2, without bpy; the Blender tests need bpy 5.0 and so run in .venv only.
set -euo pipefail
cd "$(dirname "$0")/.."
PY=${PYTHON:-python3.11}
command -v "$PY" >/dev/null 2>&1 || PY=python3
[ -x .venv-numpy2/bin/python ] || "$PY" -m venv .venv-numpy2
stamp=.venv-numpy2/.requirements.sha256
want=$(sha256sum requirements-numpy2.txt | cut -d' ' -f1)
if [ "$(cat "$stamp" 2>/dev/null)" != "$want" ]; then
    .venv-numpy2/bin/python -m pip install --quiet --upgrade pip
    .venv-numpy2/bin/python -m pip install --quiet -r requirements-numpy2.txt
    echo "$want" > "$stamp"
fi
.venv-numpy2/bin/python -c "import numpy, scipy; print('numpy', numpy.__version__, 'scipy', scipy.__version__)"
exec .venv-numpy2/bin/python -m pytest -p no:cacheprovider --ignore=tests/blender "$@"
