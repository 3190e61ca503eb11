"""The calibration file: JSON with a schema version, written atomically, verified on load.

Top-level keys: ``schema`` ("torquebench.calibration"), ``schema_version`` (1), ``sensor_id``,
``model``, ``reading_unit``, ``mass_unit`` ("g"), ``lever_arm_m``, ``coefficients``
{name: posterior mean}, ``posterior`` {name: {mean, std, p16, p50, p84}} (incl. ``sigma``),
``covariance`` {names, matrix}, ``samples`` {names, values} (thinned draws), ``diagnostics``,
``ols``, ``exact``, ``characterization``, ``data`` {path, sha256, n_readings},
``provenance``, and ``content_sha256`` = SHA-256 of the canonical JSON (sorted keys, compact)
of everything else. Load refuses another schema/version, a content hash mismatch (a corrupted or
hand-edited file), and — if given the data file — a data hash mismatch.
Without ``force`` an existing file is never replaced: the new calibration goes to ``NAME.vK.json``.
"""

from __future__ import annotations

import datetime as _dt
import hashlib
import json
import os
from pathlib import Path

import numpy as np

from userio.errors import InputError

SCHEMA = "torquebench.calibration"
SCHEMA_VERSION = 1


def _canonical(payload: dict) -> bytes:
    return json.dumps(payload, sort_keys=True, separators=(",", ":"), allow_nan=False).encode()


def _clean(obj):
    if isinstance(obj, dict):
        return {str(k): _clean(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_clean(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return _clean(obj.tolist())
    if isinstance(obj, (np.bool_, bool)):
        return bool(obj)
    if isinstance(obj, (np.integer,)):
        return int(obj)
    if isinstance(obj, (float, np.floating)):
        return float(obj) if np.isfinite(obj) else None
    return obj


def calibration_payload(fit, session, *, provenance: dict | None = None,
                        max_samples: int = 2000) -> dict:
    """The calibration document (without ``content_sha256``) for a converged fit."""
    import emcee

    from calibration.characterize import characterize

    if not fit.converged:
        raise InputError(f"{session.source}: refusing to store an unconverged fit ({fit.reason})")
    names = list(fit.coef_names)
    samples = fit.thinned(max_samples)
    q = np.quantile(samples, [0.16, 0.5, 0.84], axis=0)
    post = {n: {"mean": float(samples[:, i].mean()), "std": float(samples[:, i].std(ddof=1)),
                "p16": float(q[0, i]), "p50": float(q[1, i]), "p84": float(q[2, i])}
            for i, n in enumerate(names)}
    sig = np.exp(samples[:, -1])
    qs = np.quantile(sig, [0.16, 0.5, 0.84])
    post["sigma"] = {"mean": float(sig.mean()), "std": float(sig.std(ddof=1)),
                     "p16": float(qs[0]), "p50": float(qs[1]), "p84": float(qs[2])}
    ex = fit.exact
    exq = ex.quantiles()

    return _clean({
        "schema": SCHEMA, "schema_version": SCHEMA_VERSION,
        "sensor_id": session.sensor_id, "model": fit.model,
        "reading_unit": session.reading_unit, "mass_unit": "g",
        "lever_arm_m": session.lever_arm_m,
        "equation": "reading = slope*mass_g + offset" + {"linear": "", "quadratic": " + quad*mass_g^2",
                                                         "hysteresis": " + hysteresis*[unloading]"}[fit.model],
        "coefficients": {n: post[n]["mean"] for n in names},
        "posterior": post,
        "covariance": {"names": names, "matrix": np.cov(samples[:, :-1], rowvar=False)},
        "samples": {"names": names + ["log_sigma"], "values": samples},
        "diagnostics": {"autocorr_time": fit.autocorr_time, "tau_max": fit.tau_max,
                        "acceptance_fraction": fit.acceptance_fraction, "n_steps": fit.n_steps,
                        "n_walkers": fit.n_walkers, "burn_in": fit.burn_in,
                        "converged": fit.converged, "reason": fit.reason,
                        "mass_std_g": fit.mass_std_g, "seed": fit.seed},
        "ols": {"coefficients": dict(zip(names, ex.beta)), "r2": ex.r2, "s": float(np.sqrt(ex.s2)),
                "dof": ex.nu},
        "exact": {"note": "flat prior on coefficients, p(sigma) ~ 1/sigma: Student-t marginals",
                  "mean": dict(zip(names, ex.beta)), "std": dict(zip(names, ex.std)),
                  "p16": dict(zip(names, exq[0])), "p84": dict(zip(names, exq[2])),
                  "sigma_mean": ex.sigma_mean()},
        "characterization": characterize(session),
        "calibrated_range": {"mass_g_min": float(np.min(session.mass_g)),
                             "mass_g_max": float(np.max(session.mass_g)),
                             "reading_min": float(np.min(session.reading)),
                             "reading_max": float(np.max(session.reading))},
        "data": {"path": session.source, "sha256": session.sha256, "n_readings": len(session),
                 "meta": session.meta},
        "provenance": {"created_utc": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
                       "emcee": emcee.__version__, "numpy": np.__version__,
                       "package": __package__, **(provenance or {})},
    })


def encode(payload: dict) -> bytes:
    """The file's bytes: ``payload`` + ``content_sha256`` (SHA-256 of the canonical JSON)."""
    doc = {k: v for k, v in payload.items() if k != "content_sha256"}
    doc["content_sha256"] = hashlib.sha256(_canonical(doc)).hexdigest()
    return (json.dumps(doc, indent=1, allow_nan=False) + "\n").encode()


def save(payload: dict, path, *, force: bool = False) -> Path:
    """Write ``payload`` (+ content hash) atomically; returns the path actually written.

    Existing ``path`` and not ``force`` → the file is kept and ``NAME.vK.json`` is written.
    """
    from userio.files import write_bytes_atomic
    from userio.outputs import free_version

    data = encode(payload)
    path = Path(path)
    if force:
        return write_bytes_atomic(path, data, overwrite=True)
    target = path
    for _ in range(1000):                      # another writer may claim a version: try the next
        try:
            return write_bytes_atomic(target, data, overwrite=False)
        except InputError:
            if not target.exists():
                raise
            target = free_version(path)
    raise InputError(f"{path}: could not find a free version name")


def read_document(path, *, data_path=None) -> dict:
    """Parse and verify a calibration file (schema, version, content hash, optional data hash)."""
    from userio.files import check_input

    path = check_input(path, what="calibration JSON file")
    try:
        text = path.read_text(encoding="utf-8")
    except UnicodeDecodeError:
        raise InputError(f"{path}: not a UTF-8 JSON calibration file") from None
    try:
        doc = json.loads(text)
    except json.JSONDecodeError as exc:
        raise InputError(f"{path}: line {exc.lineno}: invalid JSON: {exc.msg}") from None
    if not isinstance(doc, dict) or doc.get("schema") != SCHEMA:
        raise InputError(f"{path}: field 'schema': not a torquebench calibration file")
    if doc.get("schema_version") != SCHEMA_VERSION:
        raise InputError(f"{path}: field 'schema_version': {doc.get('schema_version')!r} is not "
                         f"supported (this version reads {SCHEMA_VERSION})")
    stored = doc.pop("content_sha256", None)
    if stored != hashlib.sha256(_canonical(doc)).hexdigest():
        raise InputError(f"{path}: field 'content_sha256': content hash mismatch "
                         "(file corrupted or edited by hand)")
    if data_path is not None:
        digest = hashlib.sha256(check_input(data_path, "--data", max_bytes=None).read_bytes()).hexdigest()
        stored_data = doc.get("data")
        if not isinstance(stored_data, dict) or digest != stored_data.get("sha256"):
            raise InputError(f"{path}: field 'data.sha256': {data_path} is not the data this "
                             "calibration was fitted to (hash mismatch)")
    doc["content_sha256"] = stored
    check_meaning(doc, path)
    diag = doc.get("diagnostics")
    if not isinstance(diag, dict) or diag.get("converged") is not True:
        import warnings

        what = "missing" if not isinstance(diag, dict) else f"converged = {diag.get('converged')!r}"
        warnings.warn(f"{path}: field 'diagnostics': {what}: the fit's convergence is not recorded "
                      "(calibrate stores converged fits only); its ± may not hold", CalibrationWarning,
                      stacklevel=2)
    return doc


class CalibrationWarning(UserWarning):
    """A calibration file that reads but whose fit cannot be vouched for (no convergence record)."""


def check_meaning(doc: dict, path="<calibration>") -> None:
    """Refuse a hash-valid document that does not make sense (userio.schema.calibration:
    unknown model, coefficients missing or not finite, slope 0, lever arm not in (0, 10] m,
    covariance missing, not square, not symmetric or not positive semi-definite, bad samples,
    any field of the wrong type)."""
    from userio.schema import parse
    from userio.schema.calibration import CalibrationFile

    parse(CalibrationFile, doc, path)


def model_from_document(doc: dict, source: str = "<memory>"):
    """Build the :class:`calibration.model.SensorModel` of a verified document."""
    from calibration.model import SensorModel

    names = tuple(doc["covariance"]["names"])
    values = np.asarray(doc["samples"]["values"], float)
    return SensorModel(model=doc["model"], coef_names=names,
                       coef_mean=np.array([doc["coefficients"][n] for n in names]),
                       coef_cov=np.asarray(doc["covariance"]["matrix"], float).reshape(len(names), -1),
                       sigma=float(doc["posterior"]["sigma"]["mean"]),
                       samples=values[:, :len(names)], sigma_samples=np.exp(values[:, -1]),
                       lever_arm_m=doc.get("lever_arm_m"), reading_unit=doc.get("reading_unit", ""),
                       mass_range_g=calibrated_mass_range_g(doc),
                       sensor_id=doc.get("sensor_id", ""), source=source, info=doc)


def calibrated_mass_range_g(doc: dict) -> tuple[float, float] | None:
    """(min, max) applied mass (g) of the calibration session: ``calibrated_range`` if stored,
    else [0, FSO/|BFSL slope|] from the characterization (sessions start at zero load)."""
    rng = doc.get("calibrated_range")
    try:
        if rng:
            return float(rng["mass_g_min"]), float(rng["mass_g_max"])
        ch = doc["characterization"]
        span = float(ch["fso"]) / abs(float(ch["bfsl_slope"]))
        return (0.0, span) if np.isfinite(span) and span > 0 else None
    except (KeyError, TypeError, ValueError, ZeroDivisionError):
        return None


def load(path: str | os.PathLike, *, data_path=None):
    """Load a calibration file as a :class:`calibration.model.SensorModel` (verified)."""
    return model_from_document(read_document(path, data_path=data_path), source=str(path))
