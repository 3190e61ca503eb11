"""Suite-wide test set-up: the slow marker, one stage cache per run, and the CPU budget guard.

- ``@pytest.mark.slow`` tests (convergence studies, end-to-end runs of the answer-level FEM) are
  left out of a plain ``pytest`` / ``bash run.sh test`` run; ``--all`` (what ``.ci/run`` passes)
  runs them too, as does any ``-m`` expression or a test named by its node id (``file::test``).
  Slow tests are put first so that ``-n 2`` (with ``--maxschedchunk``) hands the long ones out
  before the short ones and the two workers finish together.
- ``TORQUEBENCH_CACHE`` points at ONE temporary directory for the whole run, shared by the xdist
  workers and by every ``torquebench`` subprocess: a stage (a FEM of a design, a simulation, an
  emcee fit) computed by one test is read back by the next one with the same inputs. The cache is
  content-addressed (inputs + source hashes) and written atomically, so two workers writing the
  same entry at once is safe. Tests that check cache behaviour pass their own directory.
- The guard (on the default run; ``--all`` runs everything): an unmarked test whose CPU time (this process, all threads, plus the subprocesses it
  waited for; its module- or session-scoped fixtures are charged separately) exceeds
  ``TEST_BUDGET_CPU_S`` fails with a message asking for ``@pytest.mark.slow`` or a smaller case.
  What one test pays for all the others is not charged to it, so the verdict does not depend on
  which worker took which test first: shared fixtures (computed once per run for all workers
  with ``shared_result``) and numba compiling in the test process (a cache miss on a fresh
  clone) are summed apart and listed at the end of the run.
  CPU time rather than wall time: a loaded machine slows a test down but hardly changes its CPU
  time. ``TORQUEBENCH_TEST_BUDGET_S=0`` turns the guard off (e.g. under a profiler or coverage).
"""

from __future__ import annotations

import contextlib
import hashlib
import os
import resource
import shutil
import tempfile
import time

import pytest

#: CPU seconds an unmarked test may take (its own setup + call); measured maxima of unmarked tests
#: are a few seconds, so only a test that really grew (or a new heavy one) trips it.
TEST_BUDGET_CPU_S = 20.0
#: CPU seconds a shared (module/session) fixture used by unmarked tests may take: it is paid once
#: per worker, so it may cost more than one test, not much more.
FIXTURE_BUDGET_CPU_S = 40.0
_CACHE_ENV = "TORQUEBENCH_CACHE"
_OWN_CACHE = "_TORQUEBENCH_TEST_CACHE_OWNER"


def pytest_addoption(parser):
    parser.addoption("--all", action="store_true", dest="run_all",
                     help="run the slow tests too (convergence studies, end-to-end runs); CI does")
    parser.addoption("--cpu-top", type=int, default=0, metavar="N",
                     help="list the N test files and N tests that took the most CPU seconds "
                          "(the test's own CPU plus the shared fixtures it set up; summed over workers)")


def _budget() -> float:
    raw = os.environ.get("TORQUEBENCH_TEST_BUDGET_S")
    return TEST_BUDGET_CPU_S if raw in (None, "") else float(raw)


# ---------------------------------------------------------------- one stage cache per run
def pytest_configure(config):
    """The controller (or a plain run) makes the run's cache directory; xdist workers inherit the
    environment variable, so all processes share it. Removed at the end of the run."""
    _install_jit_meter()
    if os.environ.get("PYTEST_XDIST_WORKER"):
        return
    d = tempfile.mkdtemp(prefix="torquebench-test-cache-")
    config._torquebench_cache = (d, os.environ.get(_CACHE_ENV))
    os.environ[_CACHE_ENV] = d


def pytest_unconfigure(config):
    held = getattr(config, "_torquebench_cache", None)
    if held is None:
        return
    d, before = held
    shutil.rmtree(d, ignore_errors=True)
    if before is None:
        os.environ.pop(_CACHE_ENV, None)
    else:
        os.environ[_CACHE_ENV] = before


# ---------------------------------------------------------------- selection and order
def _named_by_id(config) -> set[str]:
    return {a for a in config.args if "::" in a}


def pytest_collection_modifyitems(config, items):
    explicit_m = bool(config.getoption("markexpr", ""))
    if not (config.getoption("run_all") or explicit_m):
        named = _named_by_id(config)
        keep, slow = [], []
        for it in items:
            is_named = any(it.nodeid == n or it.nodeid.startswith(n + "[") or it.nodeid.endswith(n)
                           for n in named)
            (slow if it.get_closest_marker("slow") and not is_named else keep).append(it)
        if slow:
            config.hook.pytest_deselected(items=slow)
            items[:] = keep
            config._torquebench_slow_left_out = len(slow)
    # slow tests first (in file order, so a module's fixtures stay with its tests): with
    # `-n 2 --maxschedchunk 1` the workers take the long ones first and finish together
    order = {it.nodeid.split("::", 1)[0]: i for i, it in reversed(list(enumerate(items)))}
    rank = {id(it): (0 if it.get_closest_marker("slow") else 1, order[it.nodeid.split("::", 1)[0]], i)
            for i, it in enumerate(items)}
    items.sort(key=lambda it: rank[id(it)])

def pytest_report_header(config):
    if not (config.getoption("run_all") or config.getoption("markexpr", "")):
        return "slow tests left out (run them with --all, as CI does: bash run.sh test --all)"
    return None


def pytest_terminal_summary(terminalreporter, config):
    n = getattr(config, "_torquebench_slow_left_out", 0)
    if n:
        terminalreporter.write_line(f"{n} slow tests left out: `bash run.sh test --all` runs them (CI does)")
    top = sorted(_SHARED_SEEN.items(), key=lambda kv: -kv[1])[:6]
    if top and top[0][1] >= 1.0:
        terminalreporter.write_line("shared fixtures and numba compiling, CPU s summed over workers, charged to no test: "
                                    + ", ".join(f"{k} {v:.1f}" for k, v in top))
    if config.getoption("cpu_top", 0):
        _cpu_top(terminalreporter, config.getoption("cpu_top"))


# ---------------------------------------------------------------- the CPU budget guard
def _cpu_s() -> float:
    kids = resource.getrusage(resource.RUSAGE_CHILDREN)
    return time.process_time() + kids.ru_utime + kids.ru_stime


class _Meter:
    item = None
    start = 0.0
    shared = 0.0                 # CPU of module/session fixtures set up during this test
    shared_by: dict = {}
    depth = 0
    jit = 0.0                    # CPU of numba compiling (cache misses) in this process, ever
    jit_start = 0.0
    jit_by: dict = {}            # {kernel(signature): CPU s compiling it in this process}
    jit_by_start: dict = {}


def _kernel_name(data) -> str:
    """``module.function(argument types)`` of a numba compile event (what missed the cache)."""
    try:
        fn = data["dispatcher"].py_func
        return f"{fn.__module__}.{fn.__qualname__}({', '.join(map(str, data['args']))})"
    except Exception:                                               # pragma: no cover
        return "?"


def _install_jit_meter():
    """Count the CPU numba spends compiling (a cache miss: the first process of a fresh clone to
    call a kernel) apart from the test that happened to call it first. Only real compiles fire
    "numba:compile"; loading from the on-disk cache (cache=True) does not."""
    try:
        from numba.core import event
    except ImportError:
        return

    class JitMeter(event.Listener):
        level = 0
        t0 = 0.0

        name = ""

        def on_start(self, ev):
            if JitMeter.level == 0:
                JitMeter.t0 = time.process_time()
                JitMeter.name = _kernel_name(ev.data)
            JitMeter.level += 1

        def on_end(self, ev):
            JitMeter.level -= 1
            if JitMeter.level == 0:
                dt = time.process_time() - JitMeter.t0
                _Meter.jit += dt
                _Meter.jit_by[JitMeter.name] = _Meter.jit_by.get(JitMeter.name, 0.0) + dt

    event.register("numba:compile", JitMeter())


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_setup(item):
    _Meter.item, _Meter.start, _Meter.shared, _Meter.shared_by = item, _cpu_s(), 0.0, {}
    _Meter.jit_start, _Meter.jit_by_start = _Meter.jit, dict(_Meter.jit_by)
    yield


@pytest.hookimpl(hookwrapper=True)
def pytest_fixture_setup(fixturedef, request):
    outer = fixturedef.scope != "function" and _Meter.depth == 0     # nested ones counted once
    _Meter.depth += fixturedef.scope != "function"
    t0, jit0 = _cpu_s(), _Meter.jit
    try:
        yield
    finally:
        _Meter.depth -= fixturedef.scope != "function"
    if outer and _Meter.item is not None:
        cost = _cpu_s() - t0 - (_Meter.jit - jit0)          # compiling is counted apart
        _Meter.shared += cost
        _Meter.shared_by[fixturedef.argname] = _Meter.shared_by.get(fixturedef.argname, 0.0) + cost


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item, call):
    outcome = yield
    report = outcome.get_result()
    _record_shared(report, item)
    if call.when == "call" and item is _Meter.item:
        own = _cpu_s() - _Meter.start - _Meter.shared - (_Meter.jit - _Meter.jit_start)
        report.user_properties.append(("own_cpu_s", own))
    budget = _budget()
    if (call.when != "call" or budget <= 0 or not report.passed or item is not _Meter.item
            or item.get_closest_marker("slow") or item.config.getoption("run_all")):
        return                     # --all (CI) runs everything: the budget guards the default run
    own = _cpu_s() - _Meter.start - _Meter.shared - (_Meter.jit - _Meter.jit_start)
    heavy = {k: v for k, v in _Meter.shared_by.items() if v > FIXTURE_BUDGET_CPU_S * budget / TEST_BUDGET_CPU_S}
    msg = None
    if own > budget:
        msg = (f"test budget: this unmarked test took {own:.2f} s of CPU (budget {budget:g} s, "
               "tests/conftest.py). Mark it @pytest.mark.slow (it then runs with --all, in CI) or "
               "give it a smaller case (mesh, log, number of draws).")
    elif heavy:
        names = ", ".join(f"{k} ({v:.1f} s)" for k, v in heavy.items())
        msg = (f"test budget: shared fixture(s) {names} took more CPU than the "
               f"{FIXTURE_BUDGET_CPU_S * budget / TEST_BUDGET_CPU_S:g} s allowed for an unmarked test "
               "(tests/conftest.py). Mark the tests that use it @pytest.mark.slow or make it cheaper.")
    if msg:
        report.outcome = "failed"
        report.longrepr = msg


def _record_shared(report, item):
    """The CPU of the shared fixtures set up for this test travels with its report (xdist sends
    user_properties to the controller), so the run can list them apart from the tests."""
    if report.when == "call" and item is _Meter.item and _Meter.shared_by:
        report.user_properties.append(("shared_fixture_cpu_s", dict(_Meter.shared_by)))
    if report.when == "call" and item is _Meter.item and _Meter.jit > _Meter.jit_start:
        report.user_properties.append(("shared_fixture_cpu_s", {"(numba compiling)": _Meter.jit - _Meter.jit_start}))
        report.user_properties.append(("numba_compiled", {
            k: v - _Meter.jit_by_start.get(k, 0.0) for k, v in _Meter.jit_by.items()
            if v > _Meter.jit_by_start.get(k, 0.0)}))


_SHARED_SEEN: dict = {}
#: {nodeid: CPU s of the test itself + the shared fixtures (and compiling) set up for it}
_TEST_CPU: dict = {}
#: {kernel(signature): (CPU s compiling it, summed over workers, the first test that paid it)}
_JIT_SEEN: dict = {}


def pytest_runtest_logreport(report):
    for name, value in report.user_properties:
        if name == "shared_fixture_cpu_s":
            for k, v in value.items():
                _SHARED_SEEN[k] = _SHARED_SEEN.get(k, 0.0) + v
            _TEST_CPU[report.nodeid] = _TEST_CPU.get(report.nodeid, 0.0) + sum(value.values())
        elif name == "numba_compiled":
            for k, v in value.items():
                s, first = _JIT_SEEN.get(k, (0.0, report.nodeid))
                _JIT_SEEN[k] = (s + v, first)
        elif name == "own_cpu_s":
            _TEST_CPU[report.nodeid] = _TEST_CPU.get(report.nodeid, 0.0) + value


def _cpu_top(terminalreporter, n: int) -> None:
    """The ``--cpu-top N`` listing: the files and the tests that cost the most CPU seconds."""
    per_file: dict = {}
    for nodeid, s in _TEST_CPU.items():
        f = nodeid.split("::", 1)[0]
        per_file[f] = per_file.get(f, 0.0) + s
    w = terminalreporter.write_line
    w(f"CPU s of all tests: {sum(_TEST_CPU.values()):.1f} over {len(_TEST_CPU)} tests "
      "(own + shared fixtures + numba compiling; summed over workers)")
    w(f"the {n} costliest files, CPU s:")
    for f, s in sorted(per_file.items(), key=lambda kv: -kv[1])[:n]:
        w(f"  {s:7.1f}  {f}")
    w(f"the {n} costliest tests, CPU s:")
    for t, s in sorted(_TEST_CPU.items(), key=lambda kv: -kv[1])[:n]:
        w(f"  {s:7.1f}  {t}")
    if _JIT_SEEN:
        w(f"numba compiled in the tests (an install-time cache miss), CPU s: "
          f"{sum(v for v, _ in _JIT_SEEN.values()):.1f}; the {n} costliest kernels:")
        for k, (s, first) in sorted(_JIT_SEEN.items(), key=lambda kv: -kv[1][0])[:n]:
            w(f"  {s:7.1f}  {k}  (first: {first})")


# ---------------------------------------------------------------- shared expensive results
ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
E2E_SCENE = os.path.join(ROOT, "scenes", "end_to_end.toml")
#: the seed-independent, expensive stages of a scene: the FEM (three mesh levels), the emcee fit
#: and the noise-free simulation; what depends on the seed or the estimator stays per test
SHARED_STAGES = ("flexure", "calibration", "truth")


def run_cache_dir() -> str:
    """The run's stage cache directory ($TORQUEBENCH_CACHE, set by pytest_configure)."""
    return os.environ[_CACHE_ENV]


@contextlib.contextmanager
def run_lock(name: str):
    """An exclusive lock shared by the xdist workers of this run (flock on a file in the run's
    cache directory): the first worker computes a shared result, the other waits and reads it."""
    import fcntl

    os.makedirs(os.path.join(run_cache_dir(), "locks"), exist_ok=True)
    with open(os.path.join(run_cache_dir(), "locks", f"{name}.lock"), "w") as f:
        fcntl.flock(f, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(f, fcntl.LOCK_UN)


def shared_result(name: str, compute, *inputs):
    """``compute()`` once per run for all xdist workers: the first worker to ask computes it under
    a lock and puts it in the run's cache directory, the other waits (no CPU) and unpickles it.
    ``name`` and ``inputs`` (plain values, paths: a file's bytes are hashed) make the key. Call it
    from a module- or session-scoped fixture: the guard charges that to the fixture, not a test."""
    from torquebench.cache import Cache

    h = hashlib.sha256(name.encode())
    for x in inputs:
        h.update(repr(x).encode())
        if isinstance(x, (str, os.PathLike)) and os.path.isfile(x):
            h.update(open(x, "rb").read())
    key = h.hexdigest()[:32]                       # the cache takes hex keys only
    cache = Cache(run_cache_dir())
    with run_lock(key):
        hit = cache.get(key)
        if hit is None:
            cache.put(key, compute())
            hit = cache.get(key)
    return hit


def warm_scene(path: str, outputs=SHARED_STAGES):
    """A scene's ``outputs`` computed once per run into the shared stage cache (whichever worker
    asks first; the other waits for it, then finds them cached). → the run's Cache."""
    from torquebench import pipeline as P
    from torquebench.cache import Cache
    from torquebench.scenes import load_scene

    cache = Cache(run_cache_dir())
    scene = load_scene(path)
    with run_lock("scene-" + hashlib.sha256(os.path.abspath(path).encode()).hexdigest()[:16]):
        P.execute(scene, [o for o in outputs if o in P.BY_GIVES], cache)
    return cache


@pytest.fixture(scope="session")
def e2e_stages():
    """scenes/end_to_end.toml's FEM (the paper disc, three P2 levels), calibration fit and
    simulation in the run's stage cache, computed once for all workers. Every pipeline run with
    the default cache ($TORQUEBENCH_CACHE: `demo --flexure designs/paper_disc.toml`, `run
    scenes/end_to_end.toml`, in-process or as a subprocess) then reads them instead of re-solving."""
    return warm_scene(E2E_SCENE)


@pytest.fixture(scope="session")
def stage_cache():
    """The run's shared stage cache (torquebench.cache.Cache on $TORQUEBENCH_CACHE), nothing warmed."""
    from torquebench.cache import Cache

    return Cache(run_cache_dir())


@pytest.fixture
def private_stage_cache(tmp_path, e2e_stages):
    """A private copy of the run's stage cache, for tests that corrupt or count cache entries: it
    starts with the shared results, and what the test does to it stays in it."""
    from torquebench.cache import Cache

    d = tmp_path / "stage-cache"
    shutil.copytree(e2e_stages.dir, d, ignore=shutil.ignore_patterns("locks"))
    return Cache(d)


@pytest.fixture
def cli_inprocess(capsys, monkeypatch):
    """``torquebench ARGS`` as the CLI's ``main`` in this process → CompletedProcess (returncode,
    stdout, stderr), ``cwd`` the directory it runs in (default: unchanged). For tests of what a
    command answers (exit code, one-line error, files written or kept): the same as a subprocess
    without an interpreter start-up and import per call (≈ 0.5–1 CPU-s each); the README's and
    the help's examples run this way. A subprocess stays where the process is what is tested (the
    entry point: --version and one README example; signals, pipes, what a fresh interpreter imports)."""
    import subprocess

    from torquebench.cli import main

    def call(*argv, cwd=None):
        if cwd is not None:
            monkeypatch.chdir(cwd)
        capsys.readouterr()
        try:
            code = main([str(a) for a in argv])
        except SystemExit as e:                    # argparse's usage errors
            code = e.code
        out = capsys.readouterr()
        return subprocess.CompletedProcess(argv, code, out.out, out.err)
    return call
