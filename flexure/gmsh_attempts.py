"""An STL's meshing attempts run ahead in parallel processes: the same attempts, the same mesh, sooner.

gmsh_mesh._session tries an STL's surface strategies one after another, every strategy's first
pass, then those that left slivers once more finer around them, until a mesh has none
(flexure.stl_remesh): up to five gmsh sessions of a few seconds, one at a time (the thick disc's
STL: a failed one, then two of each of two strategies, 20 s of its 60 s adaptive run). An attempt
is a function of (strategy, spots) alone (a fresh gmsh session, deterministic), and a strategy's
next spots come from its own previous pass only (gmsh_mesh._attempt's ``finer``). So while the
decision logic waits for the attempt it asks for, the idle cores (no other process running on them, looked at every RECHECK_S) run the attempts
it may ask for next, most likely first:

    priority = (pass of the strategy, the strategy's place in the order)

(every strategy's first pass, then a strategy's second pass as soon as its first left slivers),
each in its own forked process: gmsh is single-threaded here and keeps global state, one process
per session; the fork inherits the builds, the size field and the compiled size kernel. The logic
reads the results in its own order, so the attempts record and the mesh kept are the sequential
ones, bit for bit (tests/test_stl_remesh.py); an attempt's error (InputError) is raised where the
logic reads it. Only what the logic can still ask for within its attempts is run ahead
(``Ahead._before``), and what it did not ask for is killed when it is done. The thick disc's STL,
before its re-parametrised strategy kept its first classification (flexure.stl_remesh; now one clean
pass), made five (attempts of 0.8, 5.8, 5.8, 3.4, 3.3 CPU-s: a failure, two passes of one strategy, two of
another): 11.6 CPU-s on its longest chain on two cores where one after another is 19.1 (measured
per attempt on a loaded machine; on idle cores the wall time follows the chain); a six-spoke STL
whose second strategy's first pass is clean takes it as it comes, beside the first's (4.4–5.9 s for
the mesh where the first strategy's two passes, the second needing the first's slivers, took
9.7 s). ``runner`` is sequential (in this process, nothing run ahead) with one strategy, with one
idle core (flexure.threads.count: TORQUEBENCH_THREADS=1, or a machine busy with other work) and
where ``fork`` is not available (``workers``).
"""

from __future__ import annotations

import sys

import numpy as np


#: seconds between two looks for idle cores while an attempt runs
RECHECK_S = 0.5


class Sequential:
    """Each attempt run in this process when the logic asks for it (``attempt(strategy, spots)``)."""

    def __init__(self, attempt):
        self.attempt = attempt

    def get(self, strategy: str, spots: np.ndarray):
        return self.attempt(strategy, spots)

    def close(self) -> None:
        pass


class Ahead:
    """Attempts in forked processes, at most ``workers`` run ahead of the one asked for (module
    docstring); ``budget``: the most attempts the logic makes (len(order) + QUALITY_PASSES)."""

    def __init__(self, order: list, attempt, workers: int, budget: int, fixed: bool = False):
        self.order, self.attempt, self.workers, self.budget = list(order), attempt, int(workers), int(budget)
        self.fixed = fixed
        self.running: dict = {}                     # key → (process, connection)
        self.done: dict = {}                        # key → (ok, result or exception)
        self.known = {s: [np.zeros((0, 4))] for s in self.order}    # each pass's spots, once known

    @staticmethod
    def _key(strategy, spots) -> tuple:
        spots = np.ascontiguousarray(spots, float)
        return strategy, spots.shape, spots.tobytes()

    def get(self, strategy: str, spots: np.ndarray):
        """The attempt's result (raises its exception), as ``attempt(strategy, spots)`` gives it."""
        key = self._key(strategy, spots)
        while key not in self.done:
            if key not in self.running:
                self._start(key, strategy, spots)
            self._fill()
            self._collect()
        ok, value = self.done[key]
        if ok:
            return value
        raise value

    def _fill(self) -> None:
        """Start the likeliest next attempts not yet run while fewer than ``workers`` run and no
        other process needs the core (unless ``fixed``: flexure.threads.limited, tests), of those
        the logic can still ask for (``_before``)."""
        wanted = []
        for rank, s in enumerate(self.order):
            for p, spots in enumerate(self.known[s]):
                key = self._key(s, spots)
                if key not in self.running and key not in self.done and self._before(s, p) < self.budget:
                    wanted.append((p, rank, key, s, spots))
        if not wanted:
            return
        from flexure import threads

        limit = self.workers if self.fixed else min(self.workers, threads.idle_cores(len(self.running)))
        for _, _, key, s, spots in sorted(wanted, key=lambda w: w[:2]):
            if len(self.running) >= limit:
                break
            self._start(key, s, spots)

    def _before(self, strategy: str, p: int) -> int:
        """The fewest attempts the logic makes before pass ``p`` of ``strategy`` (gmsh_mesh._session:
        every strategy's first pass, then the fewest passes first): its own ``p`` earlier passes
        and, for its first pass, one of each strategy before it in the order; for a later pass, of
        every other strategy as many as it is known to make (its passes whose spots are known: each
        but its last left slivers), up to ``p``."""
        if p == 0:
            return self.order.index(strategy)
        return p + sum(min(p, len(self.known[s])) for s in self.order if s != strategy)

    def _start(self, key, strategy, spots) -> None:
        import multiprocessing

        ctx = multiprocessing.get_context("fork")
        receive, send = ctx.Pipe(duplex=False)

        def child():
            import signal

            signal.signal(signal.SIGINT, signal.SIG_IGN)    # Ctrl-C: the parent stops and kills it
            try:
                out = (True, self.attempt(strategy, spots))
            except BaseException as exc:                     # noqa: BLE001 (handed to the parent)
                out = (False, exc)
            try:
                send.send(out)
            except Exception as exc:                          # noqa: BLE001 (unpicklable result)
                send.send((False, RuntimeError(f"mesh attempt {strategy!r}: {exc}")))

        sys.stdout.flush()                  # no buffered output copied into the child
        sys.stderr.flush()
        process = ctx.Process(target=child, daemon=True)
        process.start()
        send.close()
        self.running[key] = (process, receive)

    def _collect(self) -> None:
        """Wait for a running attempt to end (at most RECHECK_S: then ``_fill`` looks for idle
        cores again); record its result and, if it left slivers, its strategy's next pass as known."""
        from multiprocessing.connection import wait

        ready = wait([conn for _, conn in self.running.values()], timeout=RECHECK_S)
        for key in [k for k, (_, conn) in self.running.items() if conn in ready]:
            process, conn = self.running.pop(key)
            try:
                self.done[key] = conn.recv()
            except EOFError:
                self.done[key] = (False, RuntimeError(f"mesh attempt {key[0]!r}: its process died "
                                                      f"(exit code {process.exitcode})"))
            conn.close()
            process.join()
            ok, value = self.done[key]
            if ok and value[-1] is not None and key[0] in self.known:     # (a fallback is not run ahead)
                chain = self.known[key[0]]
                if any(self._key(key[0], s) == key for s in chain[-1:]):
                    chain.append(value[-1])

    def close(self) -> None:
        """Kill the attempts still running (none of them was asked for)."""
        for process, conn in self.running.values():
            process.kill()
            conn.close()
        for process, _ in self.running.values():
            process.join()
        self.running.clear()


def workers(strategies: int) -> int:
    """Processes for the attempts: the idle cores (flexure.threads.count), at most one per
    strategy; 1 (sequential) with one strategy, without ``fork`` or in a daemonic process (a Dask
    worker's, which may not have children)."""
    import multiprocessing

    from flexure import threads

    if (strategies < 2 or sys.platform != "linux" or "fork" not in multiprocessing.get_all_start_methods()
            or multiprocessing.current_process().daemon):
        return 1
    return max(1, min(threads.count(), strategies))


def runner(order: list, attempt, budget: int):
    """``get(strategy, spots)`` / ``close()`` over ``attempt(strategy, spots)`` (its result's last
    item: the spots of the strategy's next pass, or None); at most ``budget`` attempts asked for:
    Ahead on idle cores, else Sequential."""
    n = workers(len(order))
    if n < 2:
        return Sequential(attempt)
    from estimator import compiled
    from flexure import gmsh_size

    gmsh_size.warm()                        # loaded once here, not in every child: the size kernel
    if compiled.available():                # and the geometry check's (flexure.surface_distance)
        from flexure._closest_kernels import closest_on_triangles

        closest_on_triangles(np.zeros((1, 3)), np.eye(3)[None], np.array([0, 1]), np.array([0]))
    from flexure import threads

    return Ahead(order, attempt, n, budget, fixed=threads.is_limited())
