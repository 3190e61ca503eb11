"""One formatter per result: the text `run`, `demo` and a scene's report (``<scene>.md``) print for
the same stage result, so the three cannot drift apart. Pure functions of the results (SI inputs,
units in every string); no heavy imports.
"""

from __future__ import annotations


def pm(res: dict, key: str) -> str:
    """' ± x %' from ``key``'s error estimate ('' when there is none)."""
    e, v = res.get(f"{key}_error_estimate"), res.get(key)
    if e is None or v in (None, 0) or e != e:
        return ""
    return f" ± {100 * e / abs(v):.2g} %"


def mm(v) -> str:
    """A length in metres as 'x.xx mm' ('—' for None)."""
    return f"{v * 1e3:.2f} mm" if v is not None else "—"


def flexure_text(fx: dict) -> str:
    """The flexure stage's figures: strain per N·m and stiffness with their discretisation error."""
    return (f"{fx['gauge_strain_per_Nm']:.4g}{pm(fx, 'gauge_strain_per_Nm')} strain/N·m, "
            f"{fx['torsional_stiffness_Nm_per_rad']:.4g}{pm(fx, 'torsional_stiffness_Nm_per_rad')} N·m/rad "
            f"({fx['dofs']} dofs; ± discretisation error bound, 3 mesh levels)")


def sensor_text(chain) -> str:
    """The sensor chain stage: strain per N·m and the per-sample torque noise σ_τ."""
    return f"{chain.strain_per_Nm:.3g} strain/N·m, σ_τ = {chain.noise_std_Nm:.4g} N·m per sample"


def calibration_text(cal) -> str:
    """The calibration: slope ± posterior 1σ and offset, in the calibration's reading unit."""
    unit = cal.reading_unit or "reading units"
    return (f"slope {cal.coef_mean[0]:.6g} ± {cal.coef_cov[0, 0] ** 0.5:.2g} {unit}/g (posterior 1σ), "
            f"offset {cal.coef_mean[1]:.6g} {unit}")


def error_cells(measured: dict | None, predicted: dict | None, method: str) -> tuple[str, str, str]:
    """(measured RMS, predicted RMS ± MC standard error, predicted p95) of one method, as text."""
    me = (measured or {}).get(method, {}).get("position_error_rms_m")
    pr = (predicted or {}).get(method, {})
    pe = pr.get("position_rms_m_error_estimate")
    pred = f"{mm(pr.get('position_rms_m'))} ± {pe * 1e3:.2f} mm" if pe is not None else mm(pr.get("position_rms_m"))
    return mm(me), pred, mm(pr.get("position_p95_m"))


def markdown_table(header: list[str], rows: list[list[str]]) -> list[str]:
    """Lines of a markdown table."""
    return (["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
            + ["| " + " | ".join(str(c) for c in r) + " |" for r in rows])
