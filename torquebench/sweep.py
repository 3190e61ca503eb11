"""Sweeps: one scene, varied keys, run point by point on an executor.

Each point is (scene path, {dotted key: value}); it runs the stage graph with the shared cache,
so an interrupted sweep resumes from the cache and points sharing upstream stages reuse them.
Seeds come from the scene (and the point's own overrides), never from the executor: results are
identical whatever runs them. A failing point returns its error; the others are kept. Before
fanning out, the first point runs alone in this process: it computes the stages whose key is the
same at every point (the shared upstream prefix, e.g. the simulation when only the seed varies)
and imports what the stages need; forked workers inherit both.
Executors: ``local`` (in process), ``processes:N`` (process pool), ``dask://HOST:PORT``
(dask.distributed, the optional extra ``[dask]``).
"""

from __future__ import annotations

import itertools
import time
import tomllib

from userio.errors import InputError


def parse_vary(specs: list[str]) -> list[tuple[str, list]]:
    """``KEY=V1,V2`` → (key, [values]); values parsed as TOML (numbers, booleans, "strings")."""
    out = []
    for spec in specs:
        key, sep, values = spec.partition("=")
        if not sep or not key or not values:
            raise InputError(f"--vary: expected KEY=V1,V2, got {spec!r}")
        parsed = []
        for v in values.split(","):
            try:
                parsed.append(tomllib.loads(f"v = {v}")["v"])
            except tomllib.TOMLDecodeError:
                parsed.append(v)
        out.append((key.strip(), parsed))
    return out


def points(vary: list[tuple[str, list]]) -> list[dict]:
    keys = [k for k, _ in vary]
    return [dict(zip(keys, combo)) for combo in itertools.product(*(v for _, v in vary))]


def run_point(scene_path: str, overrides: dict, outputs, cache_dir) -> dict:
    """One point → {"point", "result"} or {"point", "error"} (never raises)."""
    from torquebench import pipeline as P
    from torquebench.cache import Cache
    from torquebench.stages.summary import summarize
    from torquebench.scenes import load_scene

    from torquebench.outputs import run_plan

    try:
        from estimator.spatial.scene import is_spatial_scene
        if is_spatial_scene(scene_path):          # a URDF robot: the 3-D scene runner
            from torquebench.spatial_scene import run_scene
            return {"point": overrides, "result": run_scene(scene_path, overrides)}
        scene = load_scene(scene_path, overrides)
        with run_plan(scene, outputs, force_flag=None).active():   # a point never replaces a file
            arts, timing = P.execute(scene, outputs, Cache(cache_dir))
        res = summarize(arts)
        return {"point": overrides, "result": res,
                "stages": {n: a for n, a, _ in timing}}
    except Exception as exc:      # a failing point is reported; the sweep goes on
        return {"point": overrides, "error": f"{type(exc).__name__}: {exc}"}


def shared_stages(scene_path, pts: list[dict], outputs) -> tuple[list[str], dict | None]:
    """The stages whose key is the same at every point that loads (a key covers the stage's
    inputs and its upstream keys, so these form the shared upstream prefix), and the first point
    that loads (None if none does)."""
    from torquebench import pipeline as P
    from torquebench.scenes import load_scene

    keysets, first = [], None
    for p in pts:
        try:
            steps = P.plan(load_scene(scene_path, p), outputs, None)
        except Exception:             # a failing point is reported when it runs
            continue
        first = p if first is None else first
        keysets.append({s.stage.gives: s.key for s in steps if s.key})
    if len(keysets) < 2:
        return [], first
    return [P.BY_GIVES[a].name for a, k in keysets[0].items()
            if all(ks.get(a) == k for ks in keysets[1:])], first


def _bar(total: int, progress: bool):
    """A point-by-point progress bar on stderr with the time left (tqdm's rate estimate); off
    with ``progress=False`` (--json) and whenever stderr is not a terminal."""
    import sys

    from tqdm import tqdm

    return tqdm(total=total, desc="points", unit="point", file=sys.stderr,
                disable=None if progress else True)


def run_sweep(scene_path, vary, outputs=None, executor="processes:2", cache_dir=None,
              info: dict | None = None, progress: bool = True) -> list[dict]:
    """Rows per point, in the order of the grid. Before fanning out, the first point that loads
    runs alone in this process: it computes the stages every point shares (``info``, if given,
    receives their names as ``shared_stages``) and imports what a point needs, which forked
    workers then inherit instead of each computing and importing it on an empty cache."""
    pts = points(vary)
    if len(pts) > MAX_POINTS:
        raise InputError(f"--vary: {len(pts)} points, above the {MAX_POINTS} a sweep runs; split it")
    args = [(str(scene_path), p, outputs, cache_dir) for p in pts]
    if not (executor == "local" or executor.startswith("processes") or executor.startswith("dask://")):
        raise InputError(f"--executor: expected local, processes:N or dask://HOST:PORT, got {executor!r}")
    workers = 1 if executor == "local" else _workers(executor) if executor.startswith("processes") else None
    if workers is None:
        try:
            import distributed  # noqa: F401
        except ImportError:
            raise InputError("--executor dask://: dask.distributed is not installed "
                             "(pip install -e .[dask])") from None
        _check_dask_address(executor)
    if executor == "local":
        rows = []
        with _bar(len(args), progress) as bar:
            for i, a in enumerate(args):
                t0 = time.perf_counter()
                rows.append(run_point(*a))
                bar.update()
                if i == 0 and "error" not in rows[0]:
                    _say_cost(len(pts), time.perf_counter() - t0, 1)
        return rows
    shared, first = shared_stages(str(scene_path), pts, outputs)
    if info is not None:
        info["shared_stages"] = shared
    rows = [None] * len(pts)
    if first is not None and len(pts) > 1:
        if shared:
            import sys
            print(f"sweep: the first point runs alone: it computes the stages every point shares "
                  f"({', '.join(shared)})", file=sys.stderr)
        i = pts.index(first)
        t0 = time.perf_counter()
        rows[i] = run_point(*args[i])
        if "error" not in rows[i]:
            _say_cost(len(pts), time.perf_counter() - t0, workers)
    rest = [i for i, r in enumerate(rows) if r is None]
    todo = list(zip(*(args[i] for i in rest)))
    if workers is not None:
        from concurrent.futures import ProcessPoolExecutor

        pool = ProcessPoolExecutor(workers, initializer=_ignore_sigint)
        try:
            with _bar(len(pts), progress) as bar:
                bar.update(len(pts) - len(rest))
                done = []
                for r in (pool.map(run_point, *todo) if rest else []):
                    done.append(r)
                    bar.update()
        except BaseException:          # Ctrl-C (only this process sees it): stop the workers now
            for proc in list((getattr(pool, "_processes", None) or {}).values()):
                proc.terminate()
            pool.shutdown(wait=False, cancel_futures=True)
            raise
        pool.shutdown()
    else:
        from distributed import Client

        try:
            client = Client(executor.removeprefix("dask://"), timeout=10)
        except (OSError, TimeoutError) as exc:
            raise InputError(f"--executor: cannot reach the Dask scheduler at {executor}: "
                             f"{str(exc).splitlines()[0] if str(exc) else type(exc).__name__}") from None
        with client:
            done = client.gather(client.map(run_point, *todo, pure=False)) if rest else []
    for i, r in zip(rest, done):
        rows[i] = r
    return rows


MAX_POINTS = 100_000


def _ignore_sigint() -> None:
    """A worker leaves Ctrl-C to the parent (which stops it): no traceback from every worker."""
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)


def _say_cost(n_points: int, first_s: float, workers: int | None) -> None:
    """The estimated total time, on stderr, once the first point has run (an upper bound: the
    first point also computed the stages every point shares)."""
    import sys

    if n_points < 2 or first_s * n_points / (workers or 1) < 10.0:
        return
    par = workers or 1
    total = first_s * (n_points - 1) / par
    who = f"{par} worker(s)" if workers else "one Dask worker (less on more)"
    print(f"sweep: {n_points} points; the first took {first_s:.3g} s: estimated total ≤ "
          f"{_human(total + first_s)} on {who}", file=sys.stderr)


def failed_points(rows: list[dict], what: str = "sweep") -> str | None:
    """One line when any point failed (the command then exits 2 after printing its table), else None."""
    bad = [r for r in rows if "error" in r]
    if not bad:
        return None
    pt = ", ".join(f"{k}={v}" for k, v in bad[0]["point"].items())
    head = "every point" if len(bad) == len(rows) else f"{len(bad)} of {len(rows)} points"
    return f"{what}: {head} failed (first: {pt}: {bad[0]['error']})"


def _human(seconds: float) -> str:
    return (f"{seconds:.0f} s" if seconds < 120 else f"{seconds / 60:.1f} min" if seconds < 7200
            else f"{seconds / 3600:.1f} h")


def _check_dask_address(executor: str) -> None:
    """dask://HOST:PORT: a host that resolves and a port number, before any work."""
    import socket

    addr = executor.removeprefix("dask://")
    host, sep, port = addr.rpartition(":")
    if not sep or not host or not port.isdigit() or not 0 < int(port) < 65536:
        raise InputError(f"--executor: expected dask://HOST:PORT, got {executor!r}")
    try:
        socket.getaddrinfo(host, int(port))
    except (socket.gaierror, UnicodeError, OSError) as exc:
        raise InputError(f"--executor: cannot resolve the Dask scheduler host {host!r}: {exc}") from None


def _workers(executor: str) -> int:
    _, _, n = executor.partition(":")
    try:
        workers = int(n) if n else 2
    except ValueError:
        raise InputError(f"--executor: expected processes:N, got {executor!r}") from None
    if workers < 1:
        raise InputError(f"--executor: N must be ≥ 1, got {workers}")
    return workers
