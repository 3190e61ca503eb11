"""Static-loading calibration: data, Bayesian fit (emcee), coefficient store, serial acquisition."""
