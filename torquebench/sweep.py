"""Sweeps: one scene, varied keys, run point by point on an executor.

Each point is (scene path, {dotted key: value}); it runs the stage graph with the shared cache,
so an interrupted sweep resumes from the cache and points sharing upstream stages reuse them.
Seeds come from the scene (and the point's own overrides), never from the executor: results are
identical whatever runs them. A failing point returns its error; the others are kept.
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
        scene = load_scene(scene_path, overrides)
        arts, timing = P.execute(scene, outputs, Cache(cache_dir))
        res = summarize(arts)
        return {"point": overrides, "result": res,
                "stages": {n: a for n, a, _ in timing}}
    except Exception as exc:      # a failing point is reported; the sweep goes on
        return {"point": overrides, "error": f"{type(exc).__name__}: {exc}"}


def run_sweep(scene_path, vary, outputs=None, executor="processes:2", cache_dir=None) -> list[dict]:
    pts = points(vary)
    args = [(str(scene_path), p, outputs, cache_dir) for p in pts]
    if executor == "local":
        return [run_point(*a) for a in args]
    if executor.startswith("processes"):
        _, _, n = executor.partition(":")
        try:
            workers = int(n) if n else 2
        except ValueError:
            raise InputError(f"--executor: expected processes:N, got {executor!r}") from None
        if workers < 1:
            raise InputError(f"--executor: N must be ≥ 1, got {workers}")
        from concurrent.futures import ProcessPoolExecutor

        with ProcessPoolExecutor(workers) as pool:
            return list(pool.map(run_point, *zip(*args)))
    if executor.startswith("dask://"):
        try:
            from distributed import Client
        except ImportError:
            raise InputError("--executor dask://: dask.distributed is not installed "
                             "(pip install -e .[dask])") from None
        with Client(executor.removeprefix("dask://"), timeout=10) as client:
            return client.gather(client.map(run_point, *zip(*args), pure=False))
    raise InputError(f"--executor: expected local, processes:N or dask://HOST:PORT, got {executor!r}")
