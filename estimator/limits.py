"""Physical ranges of the estimator's settings (userio.ranges.Range), declared once.

Scene fields (torquebench.scenes: ``[estimator]``, ``[sensors]``, the prediction settings) carry
these in their dataclass metadata and the command-line options of ``estimate`` and ``propagate``
check against the same objects, so a range is stated in one place with its unit and what a value
outside it usually means.
"""

from userio.ranges import Range

# observer gain K: 1/K is the residual's time constant (0.1 s⁻¹: 10 s; 1e6 s⁻¹: 1 µs)
GAIN_RANGE = Range(0.1, 1e6, "1/s", low="the residual would take longer than 10 s to follow a "
                   "contact", high="faster than any sampled sensor (1 µs time constant)")
THRESHOLD_RANGE = Range(1e-9, 1e6, "(‖r‖ in N and N·m)", low="below any sensor's noise",
                        high="above any contact a leg can feel")
SAMPLE_RATE_RANGE = Range(1.0, 1e5, "Hz", low="a log sampled slower than 1 Hz cannot follow a "
                          "contact", high="the log reader accepts periods ≥ 10 µs")
FORCE_RANGE = Range(0.0, 1e4, "N", high="kN typed as N? a leg feels at most a few kN")
ALPHA_RANGE = Range(0.0, 1.0, "(fraction of the link)")
# false alarms per sample: below 1e-15 the chi-square threshold is beyond double precision's tail
FALSE_ALARM_PER_SAMPLE_RANGE = Range(1e-15, 0.5, "per sample", low="fewer false alarms than one "
                                     "in 10^15 samples cannot be computed or verified",
                                     high="every other sample a false alarm is no detector")
