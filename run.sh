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

# shared library → Debian package: VTK's off-screen rendering (pyvista), and gmsh (STEP files)
declare -A debian=([libGL.so.1]=libgl1 [libEGL.so.1]=libegl1 [libXrender.so.1]=libxrender1
                   [libGLU.so.1]=libglu1-mesa [libXcursor.so.1]=libxcursor1 [libXft.so.2]=libxft2
                   [libXinerama.so.1]=libxinerama1 [libfontconfig.so.1]=libfontconfig1)
need_apt=()
for lib in "${!debian[@]}"; do
    ldconfig -p 2>/dev/null | grep -q "$lib" || need_apt+=("${debian[$lib]}")
done
if [ ${#need_apt[@]} -gt 0 ] && command -v apt-get >/dev/null; then
    echo "run.sh: installing Debian libraries for rendering and gmsh (${need_apt[*]})" >&2
    SUDO=""; [ "$(id -u)" = 0 ] || SUDO="sudo"
    $SUDO apt-get update -qq >&2
    DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq "${need_apt[@]}" >&2
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
