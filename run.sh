#!/usr/bin/env bash
# One entry point that sets up a fresh machine and runs the project.
#   bash run.sh demo   # the main job: a hardware-free demo scene, end to end
#   bash run.sh test   # the test suite without the slow tests (a few minutes on 2 cores)
#   bash run.sh test --all   # every test, the slow convergence and end-to-end ones too (as CI)
#   bash run.sh ...    # anything else is passed to the `torquebench` CLI
# Set-up is idempotent: Debian libraries for off-screen rendering (only if one is really missing),
# a venv in .venv, and `pip install -e .[test]` whenever pyproject.toml changed (about a minute the
# first time, nothing afterwards).
set -euo pipefail
cd "$(dirname "$0")"
VENV=${TORQUEBENCH_VENV:-.venv}
say() { echo "run.sh: $*" >&2; }

# shared library → Debian package: VTK's off-screen rendering (pyvista), and gmsh (STEP files).
# The loader cache is read ONCE into a variable: piping `ldconfig -p` into `grep -q` under pipefail
# races (grep exits early, ldconfig dies of SIGPIPE, the check fails although the library is there).
declare -A debian=([libGL.so.1]=libgl1 [libEGL.so.1]=libegl1 [libXrender.so.1]=libxrender1
                   [libGLU.so.1]=libglu1-mesa [libXcursor.so.1]=libxcursor1 [libXft.so.2]=libxft2
                   [libXinerama.so.1]=libxinerama1 [libfontconfig.so.1]=libfontconfig1)
ldcache=$(ldconfig -p 2>/dev/null || /sbin/ldconfig -p 2>/dev/null || true)
need_apt=()
for lib in "${!debian[@]}"; do
    case "$ldcache" in
        *"$lib "*|*"/$lib"*) ;;                                   # in the loader cache
        *) compgen -G "/usr/lib/*/$lib" >/dev/null || compgen -G "/usr/lib/$lib" >/dev/null \
               || need_apt+=("${debian[$lib]}") ;;               # nor on disk: really missing
    esac
done
if [ ${#need_apt[@]} -gt 0 ]; then
    SUDO=""
    if [ "$(id -u)" != 0 ]; then
        if command -v sudo >/dev/null && sudo -n true 2>/dev/null; then SUDO="sudo -n"; fi
    fi
    if ! command -v apt-get >/dev/null || { [ "$(id -u)" != 0 ] && [ -z "$SUDO" ]; }; then
        say "missing system libraries for rendering/gmsh; install them and rerun:"
        say "    apt-get install ${need_apt[*]}"
        exit 1
    fi
    say "installing Debian libraries for rendering and gmsh (${need_apt[*]})"
    aptlog=$(mktemp)
    if ! { $SUDO apt-get update -qq && DEBIAN_FRONTEND=noninteractive \
              $SUDO apt-get install -y -qq "${need_apt[@]}"; } >"$aptlog" 2>&1; then
        tail -n 5 "$aptlog" >&2
        say "could not install ${need_apt[*]} (offline? no permission?); install them and rerun"
        rm -f "$aptlog"; exit 1
    fi
    rm -f "$aptlog"
fi

# pip, quietly: drop only the machine-configuration noise ("Location ... is ignored") and
# setuptools' deprecation banners; every other line (real errors) still reaches stderr.
quiet_pip() {
    local log rc=0
    log=$(mktemp)
    PIP_DISABLE_PIP_VERSION_CHECK=1 PYTHONWARNINGS=ignore "$VENV/bin/pip" -q "$@" >"$log" 2>&1 || rc=$?
    if [ $rc -ne 0 ]; then
        grep -v "^WARNING: Location '.*' is ignored" "$log" >&2 || true
        say "pip $* failed (exit $rc)"
    fi
    rm -f "$log"
    return $rc
}

if [ ! -x "$VENV/bin/python" ]; then
    python3 -m venv "$VENV" || { say "python3 -m venv failed (on Debian: apt-get install python3-venv)"; exit 1; }
    quiet_pip install --upgrade pip || exit 1
fi
stamp="$VENV/.torquebench-installed"
if [ ! -f "$stamp" ] || [ pyproject.toml -nt "$stamp" ]; then
    say "installing torquebench and its dependencies into $VENV (about a minute the first time)"
    quiet_pip install -e ".[test]" || exit 1
    # the compiled loops (numba: estimator, CUSUM calibration, FEM multi-RHS solve) are compiled once here
    # (a failure is said, not hidden: the loops then compile inside the first runs and tests)
    warmlog=$(mktemp)
    "$VENV/bin/python" -c "from estimator import warmup; from flexure import gmsh_size, multirhs, kernels_warm, split_gs; warmup.warm(); multirhs.warm(); split_gs.warm(); gmsh_size.warm(); kernels_warm.warm()" \
        >"$warmlog" 2>&1 || say "compiling the numba loops at install failed (they compile on first use): $(grep -v '^\s*$' "$warmlog" | tail -n 1)"
    rm -f "$warmlog"
    # and the per-sample bound, release and 3-D loops, on the shipped logs (their real inputs)
    warm=$(mktemp -d)
    MPLBACKEND=Agg "$VENV/bin/torquebench" estimate examples/sim/paper_fixed_link2.csv --out "$warm/a.csv" >/dev/null 2>&1 || true
    MPLBACKEND=Agg "$VENV/bin/torquebench" estimate examples/spatial/leg_pokes.csv --robot robots/quadruped_leg.toml \
        --out "$warm/b.csv" >/dev/null 2>&1 || true
    rm -rf "$warm"
    touch "$stamp"
    say "ready: $VENV/bin/torquebench ($("$VENV/bin/torquebench" --version 2>/dev/null || echo installed));" \
        "run 'source $VENV/bin/activate' to put it on PATH, or keep using 'bash run.sh COMMAND'"
fi

export MPLBACKEND=Agg PYVISTA_OFF_SCREEN=true
case "${1:-}" in
    # 2 workers fed one test at a time (slow tests are ordered first by tests/conftest.py), so
    # neither is left alone with a long test at the end; --all is tests/conftest.py's option
    test) shift; exec "$VENV/bin/python" -m pytest -n 2 --maxschedchunk 1 -q "$@" ;;
    demo) shift; exec "$VENV/bin/torquebench" demo "$@" ;;
    *)    exec "$VENV/bin/torquebench" "$@" ;;
esac
