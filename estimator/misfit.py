"""Does one contact on the robot explain the residual? The localizer's whitened misfit, tallied.

The dynamic localizer fits r = J(α)ᵀF + n with the weights W = R⁻¹ of the detector's noise
covariance (the maximum-likelihood fit), so at the true contact the misfit

    χ² = eᵀ R⁻¹ e,   e = r − J(α̂)ᵀF̂,

is chi-square with n − 3 degrees of freedom (n residual rows; F_x, F_z and the moment μ fitted).
A log whose channels disagree with each other (one channel in kN while the rest are in N, a gain
error, a channel of another robot) gives contacts that are detected and localized with small
error bars and are nonsense: no contact explains the residual, and χ² is far in the tail on most
contact samples. Samples whose localization was flagged (α clipped, ambiguous, ...) are left out:
their misfit has its own reason.

``MisfitTally`` counts, over a stream, the well-localized contact samples whose χ² exceeds its
``TAIL`` point; ``warning`` speaks when most of them do (expected share: ``TAIL``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

TAIL = 1e-3               # the tail probability a sample's misfit is compared with
MOST = 0.5                # a warning when this share of the well-localized samples is in the tail
MIN_SAMPLES = 10          # and at least this many were localized


@dataclass
class MisfitTally:
    dof: int                               # n − 3: residual rows minus fitted unknowns
    samples: int = 0                       # well-localized contact samples seen
    in_tail: int = 0                       # of which χ² > the TAIL point
    first_s: float = np.nan                # time of the first and last sample in the tail
    last_s: float = np.nan
    worst_chi2: float = 0.0

    @property
    def threshold(self) -> float:
        """χ²_dof's upper TAIL point."""
        from scipy.special import chdtri

        return float(chdtri(self.dof, TAIL))

    def add(self, t_s: np.ndarray, cost: np.ndarray) -> None:
        """Tally samples at times ``t_s`` with the fit's cost √χ² (the localizer's ``cost``)."""
        c2 = np.asarray(cost, float) ** 2
        ok = np.isfinite(c2)
        tail = ok & (c2 > self.threshold)
        self.samples += int(ok.sum())
        self.in_tail += int(tail.sum())
        if tail.any():
            ts = np.asarray(t_s, float)[tail]
            self.first_s = float(np.nanmin([self.first_s, ts[0]]))
            self.last_s = float(np.nanmax([self.last_s, ts[-1]]))
            self.worst_chi2 = max(self.worst_chi2, float(c2[tail].max()))

    def summary(self) -> dict:
        return {"dof": self.dof, "tail_probability": TAIL, "chi2_threshold": self.threshold,
                "localized_samples": self.samples, "samples_in_tail": self.in_tail,
                "worst_chi2": self.worst_chi2 if self.in_tail else None}

    def warning(self, src: str) -> str | None:
        """One line when most well-localized contact samples are not explained by one contact."""
        if self.samples < MIN_SAMPLES or self.in_tail < MOST * self.samples:
            return None
        return (f"{src}: {self.in_tail} of {self.samples} localized contact samples "
                f"({self.first_s:.4f}–{self.last_s:.4f} s) are not explained by one contact on the "
                f"robot: misfit χ² up to {self.worst_chi2:.3g} against {self.threshold:.3g} "
                f"(the {100 * (1 - TAIL):.1f} % point with {self.dof} dof); the log's channels "
                "disagree with each other: check each channel's units and scale (Fx, Fz, My, tau…), "
                "the robot file (--robot), or more than one contact at a time")
