"""A scene run's results as JSON-ready data (SI units, unit-suffixed keys): what `run --json`
prints and what `sweep` tabulates per point."""

from __future__ import annotations


def summarize(arts: dict) -> dict:
    """JSON-ready results of the computed artifacts (SI units, unit-suffixed keys)."""
    out = {}
    if "flexure" in arts:
        out["flexure"] = arts["flexure"]
    if "chain" in arts:
        ch = arts["chain"]
        out["sensor"] = {"strain_per_Nm": ch.strain_per_Nm, "sensitivity_V_per_Nm": ch.sensitivity_V_per_Nm,
                         "torque_noise_std_Nm": ch.noise_std_Nm, "counts_per_Nm": ch.counts_per_Nm}
    if "calibration" in arts:
        cal = arts["calibration"]
        sd = float(cal.coef_cov[0, 0] ** 0.5)
        out["calibration"] = {"slope_counts_per_g": float(cal.coef_mean[0]),
                              "slope_counts_per_g_error_estimate": sd,
                              "slope_counts_per_g_error_method": "posterior standard deviation (emcee), 1σ",
                              "offset_counts": float(cal.coef_mean[1])}
        n, tau = cal.info.get("n_samples"), cal.info.get("tau_max")
        if n and tau:
            # Monte Carlo standard error of the posterior-mean slope: sd / √(N_eff), N_eff = N / τ
            out["calibration"]["slope_mean_monte_carlo_standard_error_counts_per_g"] = sd / (n / tau) ** 0.5
    if "torques" in arts:
        out["flagged_samples"] = int(arts["torques"]["flagged"].any(axis=-1).sum())
    if "estimates" in arts:     # what the detector took as the sensor noise (None: estimator default)
        out["residual_noise_source"] = arts["estimates"].get("noise_source")
    if "localization_error" in arts:
        out["measured"] = arts["localization_error"]
    if "predicted_error" in arts:
        out["predicted"] = arts["predicted_error"]
    if "report" in arts:
        out["report"] = arts["report"]
    return out
