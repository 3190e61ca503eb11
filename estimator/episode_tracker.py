"""Episodes over a stream of samples: the sums of ``estimator.episode`` kept per contact run,
split where the contact slides, in bounded memory and without a loop over samples.

A run of flagged samples is one episode unless it slides: every ``SEGMENT_SAMPLES`` fitted
samples the latest segment's own α̂ is compared with the episode's so far (both from their sums;
a vectorized solve over all segments completed in a block): a move by more than ``SPLIT_Z``
standard errors and more than the position tolerance, or to another link at a point beyond the
tolerance, ends the episode before that segment; the next starts after it (the segment mixes both
points and is left out of both fits). A run's first flagged sample is not fitted (its drive is the
onset step, estimator.onset); a split's first sample has no lag-one term with the dropped segment.
"""

from __future__ import annotations

import numpy as np

from estimator import episode as ep

SEGMENT_SAMPLES = 40
SPLIT_Z = 5.0
BLOCK = 2048                     # fitted rows per vectorized piece (bounded memory: ~6 MB)


def _decay(dt: np.ndarray, K: np.ndarray) -> np.ndarray:
    """exp(−K dt) per step and row (T, n), computed once per distinct step (regular logs: one)."""
    u, inv = np.unique(dt, return_inverse=True)
    return np.exp(-np.outer(u, K))[inv.ravel()]


class EpisodeTracker:
    """``feed`` consecutive samples; finished episodes' sum vectors queue in ``closed`` (in the
    order they end, one per run of flagged samples or per slide-split part of one); ``lay``
    reads them (estimator.episode.Layout, ``solve``)."""

    def __init__(self, robot, K, position_tol_m: float = 0.005):
        self.robot = robot if robot.floating else robot.with_base(True)
        self.N = robot.n_links
        self.K = np.asarray(K, float)
        self.tol = float(position_tol_m)
        self.lay = ep.Layout(self.N)
        self.open = None                  # the open episode's sums before its partial segment
        self.seg = None                   # the partial segment's sums (the episode: open + seg)
        self.fill = 0                     # fitted rows in the partial segment
        self.pending = False              # a split at a chunk's end: a new episode at the next row
        self.fresh = False                # the next fitted row starts an episode after a split
        self.state = None                 # the node terms' lag-one state (estimator.episode)
        self.last = None                  # (t, r, q) of the last sample seen
        self.last_fit = False             # the last sample seen was fitted
        self.closed = []

    # ------------------------------------------------------------------ episodes
    def _start(self):
        self.open = np.zeros(self.lay.size)
        self.seg = np.zeros(self.lay.size)
        self.fill = 0

    def _close(self, sums=None):
        if sums is not None:
            self.closed.append(sums)
        elif self.open is not None:
            self.closed.append(self.open + self.seg)
        self.open = self.seg = None
        self.fill = 0

    def _moved(self, snap: np.ndarray, seg: np.ndarray) -> np.ndarray:
        """(M,) bool: did the contact move between the episode so far and the segment?"""
        lay, M = self.lay, len(snap)
        ls, lg = lay.link(snap), lay.link(seg)
        r = ep.solve_many(lay, np.vstack([snap, seg]), np.maximum(np.r_[ls, lg], 1), precise=False)
        # both points at the segment's postures (α is a body coordinate; the leg may move)
        k = np.maximum(seg[:, lay.samples], 1.0)[:, None, None]
        p0 = seg[:, lay.p0].reshape(M, lay.N, 2) / k
        dl = seg[:, lay.dl].reshape(M, lay.N, 2) / k
        i = np.arange(M)
        ca, cb = np.maximum(ls, 1) - 1, np.maximum(lg, 1) - 1
        pa = p0[i, ca] + r["alpha"][:M, None] * dl[i, ca]
        pb = p0[i, cb] + r["alpha"][M:, None] * dl[i, cb]
        dist = np.hypot(*(pa - pb).T)
        se = np.hypot(r["alpha_std"][:M], r["alpha_std"][M:]) * r["length_m"][:M]
        ok = (ls > 0) & (lg > 0) & (r["reason"][:M] == 0) & (r["reason"][M:] == 0)
        far = dist > self.tol
        return ok & far & ((lg != ls) | (dist > SPLIT_Z * se))

    def _consume(self, V: np.ndarray, lagfirst: np.ndarray, samples: np.ndarray,
                 breaks: np.ndarray):
        """Bin vectors V (K, size) of one run's fitted rows, binned by segment from the current
        fill (``_rows``), with each bin's first-row lag-one terms and first sample index."""
        S = self.lay.S
        while len(V):
            if self.open is None:                     # after a split: a new episode here
                self._start()
                self.pending = False
                if self.fresh:
                    S(V)[0, :, 6:8] -= lagfirst[0]     # no lag-one term across the split
                    breaks[samples[0]] = True
                    self.fresh = False
            n_rows = V[:, self.lay.samples]
            complete = np.r_[self.fill + n_rows[0], n_rows[1:]] >= SEGMENT_SAMPLES
            nc = int(np.argmin(complete)) if not complete.all() else len(V)   # complete bins lead
            if nc == 0:
                self.seg = self.seg + V[0]
                self.fill += int(n_rows[0])
                return
            seg = V[:nc].copy()
            seg[0] += self.seg
            before = np.cumsum(np.vstack([self.open, seg[:-1]]), axis=0)   # the episode before seg j
            moved = self._moved(before, seg)
            if not moved.any():
                self.open = before[-1] + seg[-1]
                self.seg = V[nc] if nc < len(V) else np.zeros(V.shape[1])
                self.fill = int(n_rows[nc]) if nc < len(V) else 0
                return
            j = int(np.flatnonzero(moved)[0])
            self._close(before[j])                    # the episode before the moved segment
            self.fresh = True
            V, lagfirst, samples = V[j + 1:], lagfirst[j + 1:], samples[j + 1:]
            if len(V) == 0:
                self.pending = True                   # decided on the piece's last row

    # ------------------------------------------------------------------ stream
    def feed(self, t, r, q, contact, link, bound2, noise) -> np.ndarray:
        """Consecutive samples: t (T,), observer residual r (T, n), posture q (T, n) (floating
        coordinates), the flags, per-sample link and bound² of α, the drive's noise (W = Ω⁻¹, S0,
        S1 (B, n, n) per block, block index (T,)); returns ``breaks`` (T,) bool: a new episode (a
        slide) starts here."""
        T = len(t)
        breaks = np.zeros(T, bool)
        if T == 0:
            return breaks
        contact = np.asarray(contact, bool)
        link = np.asarray(link, int)
        was = self.open is not None or self.pending
        prev_c = np.r_[was, contact[:-1]]
        fit = contact & prev_c                        # not a run's first (onset) sample
        t0, r0, q0 = (t[0], r[0], q[0]) if self.last is None else self.last
        self.last = (float(t[-1]), np.array(r[-1], float), np.array(q[-1], float))
        k = np.flatnonzero(fit)
        first = ~np.r_[self.last_fit, fit[:-1]][k]     # the sample before was not fitted
        self.last_fit = bool(fit[-1])
        rowof = np.cumsum(fit) - 1
        off = np.flatnonzero(~contact)
        j = 0
        while j < T:
            if not contact[j]:
                self._close()
                self.pending = self.fresh = False
                nxt = np.flatnonzero(contact[j:])
                j = j + int(nxt[0]) if nxt.size else T
                continue
            if not prev_c[j]:                         # a run starts: its onset sample
                self._close()
                self._start()
                self.pending = self.fresh = False
                j += 1
                continue
            if self.pending:                          # the episode after a split at a chunk's end
                self.pending = False
            nxt_off = off[np.searchsorted(off, j)] if np.searchsorted(off, j) < off.size else T
            stop = int(nxt_off)
            for b in range(j, stop, BLOCK):           # fitted rows j … stop − 1, in blocks
                e = min(stop, b + BLOCK)
                rows = k[rowof[b]:rowof[e - 1] + 1]
                # bins: the segments from the current fill (a split falls on a bin's end, so the
                # next episode's segments are bins too)
                pos = np.arange(rows.size) + (self.fill if self.open is not None else 0)
                bins = pos // SEGMENT_SAMPLES
                bins -= bins[0]
                V, lagfirst = self._rows(rows, bins, t, r, q, t0, r0, q0,
                                         first[rowof[b]:rowof[e - 1] + 1], link, bound2, noise)
                heads = np.flatnonzero(np.r_[True, bins[1:] != bins[:-1]])
                self._consume(V, lagfirst, b + heads, breaks)
            j = stop
        if self.pending and not contact[-1]:
            self.pending = False
        return breaks

    def _rows(self, rows, bins, t, r, q, t0, r0, q0, first, link, bound2, noise):
        """Bin vectors (K, size) of the fitted samples ``rows`` (indices into this feed) summed by
        ``bins``, and each bin's first-row lag-one terms (K, N, 2, G)."""
        Wb, S0b, S1b, widx = noise
        prev = rows - 1
        ok = prev >= 0
        pi = np.maximum(prev, 0)
        tp = np.where(ok, t[pi], t0)
        rp = np.where(ok[:, None], r[pi], r0)
        qp = np.where(ok[:, None], q[pi], q0)
        a = _decay(t[rows] - tp, self.K)               # the step's own coefficients
        x = (r[rows] - a * rp) / (1.0 - a)            # the drive: step mean of τ_ext
        lk = np.clip(link[rows], 1, self.N)
        K = int(bins[-1]) + 1
        sums, lagfirst, ext, self.state = ep.binned_terms(self.robot, x, 0.5 * (q[rows] + qp), q[rows], lk,
                                                          Wb, S0b, S1b, widx[rows], first, bins, K,
                                                          self.state)
        return self.lay.bins(sums, ext, lk, bound2[rows], bins, K), lagfirst

    def finish(self):
        self._close()
        self.pending = self.fresh = False
