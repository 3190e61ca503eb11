"""Characterization figures as calibration standards state them, in % of full-scale output.

FSO = |ŷ(m_max) − ŷ(m_min)| of the best-fit straight line (BFSL, OLS on all readings).
- non-linearity: max over levels of |mean loading reading − BFSL| / FSO · 100
- hysteresis:    max over levels of |mean unloading − mean loading| / FSO · 100 (NaN without unloading)
- repeatability: max over levels and directions of (max − min across repeats) / FSO · 100
  (NaN with a single repeat)
"""

from __future__ import annotations

import numpy as np

from calibration.session import Session


def characterize(session: Session) -> dict:
    """Non-linearity, hysteresis, repeatability (% FSO) and the BFSL."""
    m, y = session.mass_g, session.reading
    slope, offset = np.polyfit(m, y, 1)
    fso = abs(slope) * (m.max() - m.min())
    levels = np.unique(m)
    load = ~session.unload

    def level_stat(mask, fn):
        out = np.full(levels.size, np.nan)
        for k, lv in enumerate(levels):          # loop over ≤ tens of load levels
            sel = mask & (m == lv)
            if sel.any():
                out[k] = fn(y[sel])
        return out

    mean_load = level_stat(load, np.mean)
    mean_unload = level_stat(~load, np.mean)
    nonlin = np.nanmax(np.abs(mean_load - (slope * levels + offset))) / fso * 100
    hyst = (np.nanmax(np.abs(mean_unload - mean_load)) / fso * 100
            if np.any(np.isfinite(mean_unload - mean_load)) else float("nan"))
    if np.unique(session.repeat).size > 1:
        rng_load = level_stat(load, np.ptp)
        rng_unload = level_stat(~load, np.ptp)
        rep = np.nanmax(np.concatenate([rng_load, rng_unload])) / fso * 100
    else:
        rep = float("nan")
    return {"fso": float(fso), "bfsl_slope": float(slope), "bfsl_offset": float(offset),
            "nonlinearity_pct_fs": float(nonlin), "hysteresis_pct_fs": float(hyst),
            "repeatability_pct_fs": float(rep)}
