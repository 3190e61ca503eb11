"""Static-loading calibration: data, Bayesian fit (emcee), coefficient store, serial acquisition.

``calibration.load(path)`` → a :class:`calibration.model.SensorModel` with ``torque(reading)``,
``torque_std(reading)`` and ``sample_coefficients(n, rng)``. Heavy imports (emcee, serial,
matplotlib) happen inside the functions that use them.
"""


def load(path, *, data_path=None):
    """Load and verify a calibration file (schema, content hash; data hash if ``data_path``)."""
    from calibration.store import load as _load
    return _load(path, data_path=data_path)
