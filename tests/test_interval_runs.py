"""The one base of the stream's interval accumulators (estimator.interval_runs.IntervalRuns): the
intervals a log is split into do not depend on where its chunks end, and both accumulators
(EpisodeAccumulator, SteadyForce) close the same intervals in the same order."""

import numpy as np
import pytest

from estimator.interval_runs import IntervalRuns
from estimator.interval_summary import EpisodeAccumulator
from estimator.intervals import SteadyForce


class Spans(IntervalRuns):
    """Records each interval as [first sample, samples] (global indices)."""

    def feed(self, g0, contact, breaks):
        starts, stops, continued, _ = self.runs(contact, breaks)

        def add(ep, i, a, b):
            ep[1] += b - a

        self.extend(starts, stops, continued, len(contact), lambda a: [g0 + a, 0], add)


def _truth(contact, breaks):
    """Intervals of the whole log at once, by a plain loop."""
    out, cur = [], None
    for k, (c, br) in enumerate(zip(contact, breaks)):
        if c and (cur is None or br):
            if cur is not None:
                out.append(cur)
            cur = [k, 0]
        if c:
            cur[1] += 1
        elif cur is not None:
            out.append(cur)
            cur = None
    if cur is not None:
        out.append(cur)
    return out


@pytest.mark.parametrize("seed", range(6))
def test_intervals_do_not_depend_on_the_chunks(seed):
    rng = np.random.default_rng(seed)
    T = 400
    contact = np.repeat(rng.random(40) < 0.5, 10) & (rng.random(T) < 0.97)
    breaks = contact & (rng.random(T) < 0.02)
    cuts = np.sort(rng.choice(np.arange(1, T), 7, replace=False))
    acc = Spans(2)
    for a, b in zip(np.r_[0, cuts], np.r_[cuts, T]):
        acc.feed(a, contact[a:b], breaks[a:b])
    acc.finish()
    assert acc.closed == _truth(contact, breaks)


def test_both_accumulators_close_the_same_intervals():
    rng = np.random.default_rng(3)
    T, n = 300, 2
    contact = np.repeat(rng.random(30) < 0.5, 10)
    breaks = contact & (rng.random(T) < 0.02)
    link = np.where(contact, 1 + (rng.random(T) < 0.3), 0)
    alpha, Fx, Fz, px, pz = rng.random((5, T))
    force = np.c_[Fx, Fz]
    ep, sf = EpisodeAccumulator(n), SteadyForce(n, 100.0)
    for a, b in ((0, 77), (77, 150), (150, 151), (151, T)):
        s = slice(a, b)
        ep.feed(a, np.arange(a, b) * 1e-3, contact[s], link[s], alpha[s], Fx[s], Fz[s], px[s], pz[s],
                np.zeros((b - a, 3)), np.zeros((3, b - a)), breaks=breaks[s])
        sf.feed(contact[s], link[s], force[s], np.full(b - a, 1.0), breaks[s])
    ep.finish()
    sf.finish()
    assert len(ep.closed) == len(sf.closed) == len(_truth(contact, breaks)) > 3
    for e, f, (k0, L) in zip(ep.closed, sf.closed, _truth(contact, breaks)):
        assert e["n"] == L and round(e["t0"] * 1e3) == k0
        assert f[SteadyForce.KEYS.index("n_all")].sum() == L          # every sample of it, all links
        on = np.arange(k0, k0 + L)
        assert e["sums"]["Fx"].sum() == pytest.approx(Fx[on].sum())
        assert f[SteadyForce.KEYS.index("Fx_all")].sum() == pytest.approx(Fx[on].sum())
