"""Figures: corner plot of the posterior, residual plot, torque-fidelity plot (matplotlib/corner
imported inside the functions). Each writes one PNG to the path it is given."""

from __future__ import annotations

import numpy as np


def _plt():
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt


def corner_plot(fit, path, title: str = "") -> None:
    """Corner plot of the emcee samples (coefficients + σ), exact Student-t marginals overlaid."""
    import corner
    from scipy import stats

    plt = _plt()
    samples = fit.samples.copy()
    samples[:, -1] = np.exp(samples[:, -1])
    labels = list(fit.coef_names) + ["sigma"]
    fig = corner.corner(samples, labels=labels, quantiles=[0.16, 0.5, 0.84], show_titles=True,
                        title_fmt=".4g", plot_datapoints=False, truth_color="C1")
    axes = np.array(fig.axes).reshape(len(labels), len(labels))
    ex = fit.exact
    sd = np.sqrt(np.diag(ex.scale))
    for i in range(len(fit.coef_names)):
        ax = axes[i, i]
        lo, hi = ax.get_xlim()
        x = np.linspace(lo, hi, 200)
        pdf = stats.t.pdf((x - ex.beta[i]) / sd[i], ex.nu) / sd[i]
        counts, edges = np.histogram(samples[:, i], bins=20, range=(lo, hi))
        ax.plot(x, pdf * counts.sum() * (edges[1] - edges[0]), color="C1", lw=1.2)
    if title:
        fig.suptitle(title + "  (orange: exact Student-t)", y=1.02)
    fig.savefig(path, dpi=90, bbox_inches="tight", format="png")
    plt.close(fig)


def residual_plot(session, fit, path, title: str = "") -> None:
    """Residuals reading − model (posterior mean) vs mass, loading/unloading marked, ±2σ band."""
    from calibration.posterior import design_matrix

    plt = _plt()
    X = design_matrix(session.mass_g, fit.model, session.unload)
    resid = session.reading - X @ fit.mean[:-1]
    sig = fit.sigma
    fig, ax = plt.subplots(figsize=(6.4, 3.6))
    for mask, label, mk in ((~session.unload, "loading", "o"), (session.unload, "unloading", "v")):
        if mask.any():
            ax.plot(session.mass_g[mask], resid[mask], mk, ms=4, label=label, alpha=0.8)
    ax.axhline(0, color="k", lw=0.8)
    ax.axhspan(-2 * sig, 2 * sig, color="C2", alpha=0.15, label="±2σ")
    ax.set_xlabel("applied mass (g)")
    ax.set_ylabel(f"residual ({session.reading_unit})")
    ax.set_title(title or f"{fit.model} fit residuals")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=100, format="png")
    plt.close(fig)


def fidelity_plot(result: dict, path) -> None:
    """Paper Fig. 3: truth, strain-gauge sensor and motor-current estimate vs time, and errors."""
    plt = _plt()
    t = result["t_s"]
    fig, (ax, ax2) = plt.subplots(2, 1, figsize=(7.5, 5.2), sharex=True,
                                  gridspec_kw={"height_ratios": [2, 1]})
    s, m = result["sensor"], result["motor_current"]
    ax.plot(t, result["motor_Nm"], color="C3", lw=0.6, alpha=0.7,
            label=f"motor current (R²={m['r2']:.4f}, MAE={m['mae_Nm']:.4f} N·m)")
    ax.plot(t, result["sensor_Nm"], color="C0", lw=0.8,
            label=f"strain-gauge sensor (R²={s['r2']:.5f}, MAE={s['mae_Nm']:.4f} N·m)")
    ax.plot(t, result["truth_Nm"], "k--", lw=1.0, label="ground truth")
    ax.set_ylabel("torque (N·m)")
    ax.legend(fontsize=8, loc="upper left")
    ax2.plot(t, result["motor_Nm"] - result["truth_Nm"], color="C3", lw=0.5)
    ax2.plot(t, result["sensor_Nm"] - result["truth_Nm"], color="C0", lw=0.6)
    ax2.set_ylabel("error (N·m)")
    ax2.set_xlabel("time (s)")
    fig.tight_layout()
    fig.savefig(path, dpi=100, format="png")
    plt.close(fig)
