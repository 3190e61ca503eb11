#!/usr/bin/env bash
# One entry point that sets up a fresh machine and runs the project.
#   bash run.sh demo   # the main job: a hardware-free demo scene, end to end
#   bash run.sh test   # the test suite
#   bash run.sh ...    # anything else is passed to the `torquebench` CLI
# Set-up is idempotent: Debian libraries for off-screen rendering (if missing), a venv in .venv,
# and `pip install -e .[test]` whenever pyproject.toml changed.
set -euo pipefail
cd "$(dirname "$0")"
VENV=${TORQUEBENCH_VENV:-.venv}

need_apt=()
for lib in libGL.so.1 libEGL.so.1 libXrender.so.1; do
    ldconfig -p 2>/dev/null | grep -q "$lib" || need_apt+=("$lib")
done
if [ ${#need_apt[@]} -gt 0 ] && command -v apt-get >/dev/null; then
    echo "run.sh: installing Debian libraries for off-screen rendering (${need_apt[*]})" >&2
    SUDO=""; [ "$(id -u)" = 0 ] || SUDO="sudo"
    $SUDO apt-get update -qq >&2
    DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq libgl1 libegl1 libxrender1 >&2
fi

if [ ! -x "$VENV/bin/python" ]; then
    python3 -m venv "$VENV"
    "$VENV/bin/pip" install -q --upgrade pip >&2
fi
stamp="$VENV/.torquebench-installed"
if [ ! -f "$stamp" ] || [ pyproject.toml -nt "$stamp" ]; then
    "$VENV/bin/pip" install -q -e ".[test]" >&2
    touch "$stamp"
fi

export MPLBACKEND=Agg PYVISTA_OFF_SCREEN=true
case "${1:-}" in
    test) shift; exec "$VENV/bin/python" -m pytest -n 2 -q "$@" ;;
    demo) shift; exec "$VENV/bin/torquebench" demo "$@" ;;
    *)    exec "$VENV/bin/torquebench" "$@" ;;
esac
