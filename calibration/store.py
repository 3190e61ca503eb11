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

from calibration.errors import InputError

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
    import calibration
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
                       "package": calibration.__name__, **(provenance or {})},
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
    from userio.files import next_version_path, write_bytes_atomic

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
            target = next_version_path(path)
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
    return doc


MODEL_COEFS = {"linear": ("slope", "offset"), "quadratic": ("slope", "offset", "quad"),
               "hysteresis": ("slope", "offset", "hysteresis")}


def check_meaning(doc: dict, path="<calibration>") -> None:
    """Refuse a hash-valid document that does not make sense: unknown model, coefficients
    missing or not finite, slope 0, lever arm not finite > 0, covariance missing, not square,
    not symmetric or not positive semi-definite (eigenvalues ≥ −1e-9·max|λ|), bad samples; and
    any field of the wrong type (a string where a number belongs, a number where a table does)."""
    try:
        _check_meaning(doc, path)
    except (TypeError, ValueError, KeyError, AttributeError, IndexError) as exc:
        if isinstance(exc, InputError):
            raise
        raise InputError(f"{path}: a field has the wrong type or shape ({type(exc).__name__}: "
                         f"{str(exc).splitlines()[0] if str(exc) else ''}); not a calibration this "
                         "version wrote") from None


def _number(doc_value, name: str, **kw) -> float:
    """A JSON number (not a string, not a boolean), finite (userio.errors.finite rules)."""
    from userio.errors import finite

    if isinstance(doc_value, bool) or not isinstance(doc_value, (int, float)):
        raise InputError(f"{name}: expected a number, got {doc_value!r}")
    return finite(doc_value, name, **kw)


def _check_meaning(doc: dict, path) -> None:
    finite = _number

    def field(name):
        return f"{path}: field {name!r}"

    model = doc.get("model")
    if model not in MODEL_COEFS:
        raise InputError(f"{field('model')}: unknown model {model!r} "
                         f"(known: {', '.join(MODEL_COEFS)})")
    names = MODEL_COEFS[model]
    coefs = doc.get("coefficients")
    if not isinstance(coefs, dict) or set(coefs) != set(names):
        raise InputError(f"{field('coefficients')}: model {model!r} needs exactly {', '.join(names)}")
    for n in names:
        finite(coefs[n], f"{path}: field 'coefficients.{n}'")
    if coefs["slope"] == 0:
        raise InputError(f"{field('coefficients.slope')}: slope is 0; readings carry no load information")
    if doc.get("lever_arm_m") is not None:
        from calibration.session import LEVER_ARM_RANGE_M

        finite(doc["lever_arm_m"], f"{path}: field 'lever_arm_m'", positive=True)
        LEVER_ARM_RANGE_M.check(doc["lever_arm_m"], f"{path}: field 'lever_arm_m'")
    for key in ("reading_unit", "sensor_id"):
        if key in doc and not isinstance(doc[key], str):
            raise InputError(f"{field(key)}: expected a string, got {doc[key]!r}")
    cov = doc.get("covariance")
    if not isinstance(cov, dict) or "matrix" not in cov or "names" not in cov:
        raise InputError(f"{field('covariance')}: missing (need names and matrix); "
                         "the torque uncertainty cannot be computed without it")
    if not isinstance(cov["names"], list) or list(cov["names"]) != list(names):
        raise InputError(f"{field('covariance.names')}: expected {list(names)}, got {cov['names']!r}")
    try:
        mat = np.asarray(cov["matrix"], float)
    except (TypeError, ValueError):
        raise InputError(f"{field('covariance.matrix')}: not a numeric matrix") from None
    p = len(names)
    if mat.shape != (p, p) or not np.all(np.isfinite(mat)):
        raise InputError(f"{field('covariance.matrix')}: expected a finite {p}×{p} matrix")
    if not np.allclose(mat, mat.T, rtol=1e-9, atol=0):
        raise InputError(f"{field('covariance.matrix')}: not symmetric")
    lam = np.linalg.eigvalsh(mat)
    if lam.min() < -1e-9 * max(abs(lam).max(), 1e-300):
        raise InputError(f"{field('covariance.matrix')}: not positive semi-definite "
                         f"(eigenvalue {lam.min():.3g})")
    try:
        finite(doc["posterior"]["sigma"]["mean"], f"{path}: field 'posterior.sigma.mean'", nonneg=True)
        vals = np.asarray(doc["samples"]["values"], float)
    except (KeyError, TypeError, ValueError, InputError):
        raise InputError(f"{field('samples')}: posterior samples or sigma missing or not numeric") from None
    if vals.ndim != 2 or vals.shape[0] < 1 or vals.shape[1] != p + 1 or not np.all(np.isfinite(vals)):
        raise InputError(f"{field('samples.values')}: expected finite draws of shape (S, {p + 1})")


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
