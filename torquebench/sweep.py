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
    from torquebench.commands.run import summarize
    from torquebench.scenes import load_scene

    try:
        from estimator.spatial.scene import is_spatial_scene
        if is_spatial_scene(scene_path):          # a URDF robot: the 3-D scene runner
            from torquebench.spatial_scene import run_scene
            return {"point": overrides, "result": run_scene(scene_path, overrides)}
        scene = load_scene(scene_path, overrides)
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


def run_sweep(scene_path, vary, outputs=None, executor="processes:2", cache_dir=None,
              info: dict | None = None) -> list[dict]:
    """Rows per point, in the order of the grid. Before fanning out, the first point that loads
    runs alone in this process: it computes the stages every point shares (``info``, if given,
    receives their names as ``shared_stages``) and imports what a point needs, which forked
    workers then inherit instead of each computing and importing it on an empty cache."""
    pts = points(vary)
    args = [(str(scene_path), p, outputs, cache_dir) for p in pts]
    if executor == "local":
        return [run_point(*a) for a in args]
    if not (executor.startswith("processes") or executor.startswith("dask://")):
        raise InputError(f"--executor: expected local, processes:N or dask://HOST:PORT, got {executor!r}")
    workers = _workers(executor) if executor.startswith("processes") else None
    if workers is None:
        try:
            import distributed  # noqa: F401
        except ImportError:
            raise InputError("--executor dask://: dask.distributed is not installed "
                             "(pip install -e .[dask])") from None
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
        rows[i] = run_point(*args[i])
    rest = [i for i, r in enumerate(rows) if r is None]
    todo = list(zip(*(args[i] for i in rest)))
    if workers is not None:
        from concurrent.futures import ProcessPoolExecutor

        with ProcessPoolExecutor(workers) as pool:
            done = list(pool.map(run_point, *todo)) if rest else []
    else:
        from distributed import Client

        with Client(executor.removeprefix("dask://"), timeout=10) as client:
            done = client.gather(client.map(run_point, *todo, pure=False)) if rest else []
    for i, r in zip(rest, done):
        rows[i] = r
    return rows


def _workers(executor: str) -> int:
    _, _, n = executor.partition(":")
    try:
        workers = int(n) if n else 2
    except ValueError:
        raise InputError(f"--executor: expected processes:N, got {executor!r}") from None
    if workers < 1:
        raise InputError(f"--executor: N must be ≥ 1, got {workers}")
    return workers
