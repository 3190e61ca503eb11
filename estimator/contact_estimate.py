"""The estimator's answer per log sample: ``ContactEstimate`` (detection, link, α, force, point,
flags and the observer residual), its contact intervals and its summary."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from estimator import localization as loc_mod

FRAME_COLUMNS = ["t", "contact", "link", "alpha", "Fx", "Fz", "px", "pz", "rnorm"]


@dataclass
class ContactEstimate:
    """Per-sample arrays (T,) unless noted. link is 1-based, 0 = no contact; F ON the robot."""

    t: np.ndarray
    contact: np.ndarray         # bool: unexpected contact detected
    link: np.ndarray            # int
    alpha: np.ndarray           # NaN when no contact or ill-conditioned (see reason)
    Fx: np.ndarray
    Fz: np.ndarray
    px: np.ndarray
    pz: np.ndarray
    rnorm: np.ndarray           # ‖r‖ (of the unexpected part) compared with the threshold
    condition: np.ndarray       # 1/|sin∠(F, link)|, NaN without contact
    reason: np.ndarray          # int8 index into estimator.localization.REASONS
    residual: np.ndarray        # (T, n) observer residual r ≈ τ_ext, floating coordinates
    method: str = "dynamic"
    expected_force_N: np.ndarray | None = None     # (T, m, 2) at the expected contacts
    n_skipped: int = 0          # log rows skipped for NaN/inf fields
    info: dict = field(default_factory=dict)
    interval_list: list | None = None   # contact intervals (``EpisodeSummary``), with error estimates

    def reason_names(self) -> np.ndarray:
        return np.asarray(loc_mod.REASONS, dtype=object)[self.reason]

    def to_frame(self):
        """pandas DataFrame ``t,contact,link,alpha,Fx,Fz,px,pz,rnorm`` (contact as 0/1)."""
        import pandas as pd

        return pd.DataFrame({"t": self.t, "contact": self.contact.astype(int), "link": self.link,
                             "alpha": self.alpha, "Fx": self.Fx, "Fz": self.Fz, "px": self.px,
                             "pz": self.pz, "rnorm": self.rnorm}, columns=FRAME_COLUMNS)

    def intervals(self) -> list[dict]:
        """Contact intervals: start/end time, samples, the most frequent link, mean α, F, p over
        the samples with a well-conditioned answer on that link (NaN if none), and the 1σ error
        estimates (``EpisodeSummary``)."""
        return list(self.interval_list or [])

    def summary(self) -> dict:
        reasons = self.reason_names()[self.contact]
        names, counts = np.unique(reasons, return_counts=True) if reasons.size else ([], [])
        return {"method": self.method, "samples": int(len(self.t)), "skipped_samples": self.n_skipped,
                "contact_samples": int(self.contact.sum()),
                "flags_during_contact": {str(k): int(v) for k, v in zip(names, counts)},
                "intervals": self.intervals(), **self.info}
