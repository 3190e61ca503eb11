"""Tick labels of a log axis that stay readable whatever the data's range.

matplotlib labels the minor ticks of a log axis that spans less than about a decade (2×10³, 3×10³,
… in scientific notation), and on a sweep's narrow range those labels run into each other. Here:
over more than a decade, the decades (``LogLocator``) and no minor labels; over less, at most
``MAX_TICKS`` round values inside the data's range (``MaxNLocator`` on the values) as fixed ticks,
written as plain numbers (as many digits as their spacing needs); minor ticks stay, unlabelled.
"""

from __future__ import annotations

import numpy as np

MAX_TICKS = 5


def readable_log_ticks(axis, values) -> None:
    """Set ``axis`` (a matplotlib XAxis/YAxis on a log scale) to readable ticks for ``values``."""
    from matplotlib import ticker

    v = np.asarray(values, float)
    v = v[np.isfinite(v) & (v > 0)]
    axis.set_minor_formatter(ticker.NullFormatter())
    if v.size == 0:
        return
    lo, hi = float(v.min()), float(v.max())
    if hi / lo > 10.0:
        axis.set_major_locator(ticker.LogLocator(base=10.0, numticks=MAX_TICKS + 1))
        axis.set_major_formatter(ticker.LogFormatterSciNotation())
        return
    if hi == lo:
        ticks = [lo]
    else:
        ticks = [t for t in ticker.MaxNLocator(nbins=MAX_TICKS - 1, steps=[1, 2, 2.5, 5, 10]).tick_values(lo, hi)
                 if lo * 0.98 <= t <= hi * 1.02 and t > 0]
    axis.set_major_locator(ticker.FixedLocator(ticks))
    plain = ticker.ScalarFormatter(useOffset=False)
    plain.set_scientific(False)
    axis.set_major_formatter(plain)
