"""Command-line values the commands share: comma-separated numbers, the model-uncertainty option
and the identification's prior (planar and URDF paths alike)."""

from __future__ import annotations

import math

from userio.errors import InputError

DEFAULT_PRIOR = 0.3        # identify's prior when neither --prior nor the file's [model_uncertainty]


def floats(text, where, count=None) -> list[float]:
    """'1,2.5,3' → [1.0, 2.5, 3.0]; ``count`` values if given (one line naming ``where`` otherwise)."""
    try:
        values = [float(v) for v in str(text).split(",")]
    except ValueError:
        raise InputError(f"{where}: expected comma-separated numbers, got {text!r}") from None
    if count is not None and len(values) != count:
        raise InputError(f"{where}: expected {count} values, got {len(values)}")
    return values


def model_uncertainty_option(text):
    """--model-uncertainty REL | none → ModelUncertainty, False, or None (not given)."""
    from estimator.model import ModelUncertainty

    if text is None:
        return None
    if str(text).strip().lower() == "none":
        return False
    rel = floats(text, "--model-uncertainty", 1)[0]
    if not (math.isfinite(rel) and 0 < rel <= 1):
        raise InputError(f"--model-uncertainty: expected a relative 1σ in (0, 1] or 'none', got {text!r}")
    return ModelUncertainty.uniform(rel)


def fit_prior(prior_option, robot, robot_path):
    """(ModelUncertainty, source) the fit's prior: ``--prior REL``, else the robot file's
    [model_uncertainty], else DEFAULT_PRIOR; every σ must be > 0."""
    from estimator.model import ModelUncertainty

    if prior_option is not None:
        if not (math.isfinite(prior_option) and 0 < prior_option <= 1):
            raise InputError(f"--prior: must be in (0, 1], got {prior_option}")
        prior, source = ModelUncertainty.uniform(prior_option), "--prior"
    elif robot.model_uncertainty is not None:
        prior, source = robot.model_uncertainty, f"{robot_path}: [model_uncertainty]"
    else:
        prior, source = ModelUncertainty.uniform(DEFAULT_PRIOR), "default"
    if prior.mass_rel <= 0 or prior.inertia_rel <= 0 or (prior.com_m is not None and prior.com_m <= 0) \
            or (prior.com_m is None and not (prior.relative or 0) > 0):
        raise InputError(f"prior ({source}): every σ must be > 0 to serve as the fit's prior")
    return prior, source
