"""Contact intervals across chunk boundaries, the base of the stream's interval accumulators.

An interval is a run of flagged samples, split where the contact slides (``breaks``); a run open
at the end of one part continues into the next. Per interval a subclass keeps running sums binned
by link (bounded memory): ``estimator.interval_summary.EpisodeAccumulator`` (means of α, F, p, the
representative sample) and ``estimator.intervals.SteadyForce`` (the rise-corrected mean force).
Both see the same intervals, closed in the same order.
"""

from __future__ import annotations

import numpy as np


class IntervalRuns:
    """The open interval, the closed ones (in order), and how a part's samples extend them."""

    def __init__(self, n_links: int):
        self.nb = n_links + 1            # link 0: no link
        self.open = None
        self.closed = []

    def runs(self, contact, breaks=None):
        """The part's intervals as ``(starts, stops, continued, sid)``: sample ranges [a, b) (b == T:
        still open at the part's end), whether the first continues the open interval, and each
        sample's interval index (valid where flagged). A break at sample 0 closes the open one; a
        break at a run's first sample is that run's start (no empty interval)."""
        c = np.asarray(contact, bool).astype(np.int8)
        if breaks is not None and len(c) and breaks[0] and self.open is not None:
            self.closed.append(self.open)
            self.open = None
        continued = self.open is not None
        edges = np.diff(np.concatenate([[int(continued)], c, [0]]))
        starts, stops = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
        if continued:
            starts = np.r_[0, starts]
        if breaks is not None:
            cut = np.flatnonzero(np.asarray(breaks, bool) & c.astype(bool))
            cut = cut[(cut > 0) & ~np.isin(cut, starts)]     # a break where a run starts adds nothing
            starts, stops = np.sort(np.r_[starts, cut]), np.sort(np.r_[stops, cut])
        sid = np.searchsorted(starts, np.arange(len(c)), side="right") - 1
        return starts, stops, continued, sid

    def binned(self, key, n_runs: int, columns) -> list:
        """Per (interval, link) sums, key = sid·nb + link per sample: for each ``(samples,
        weights)`` of ``columns`` (sample indices in order; weights None: counts) an (S, nb) array
        Σ weights over those samples (summed in sample order)."""
        size = n_runs * self.nb
        return [np.bincount(key[m], weights=None if w is None else w[m], minlength=size).reshape(n_runs, self.nb)
                for m, w in columns]

    def extend(self, starts, stops, continued: bool, T: int, new, add) -> None:
        """Each interval of the part: the open one (continued) or ``new(a)``, extended by
        ``add(ep, i, a, b)``; closed when it ends inside the part, else left open."""
        for i in range(len(starts)):
            a, b = int(starts[i]), int(stops[i])
            ep = self.open if (i == 0 and continued) else new(a)
            add(ep, i, a, b)
            if b < T:
                self.closed.append(ep)
                self.open = None
            else:
                self.open = ep

    def finish(self) -> None:
        """The end of the log: the open interval is closed."""
        if self.open is not None:
            self.closed.append(self.open)
            self.open = None
