"""torquebench: the composition layer (scenes, pipeline, CLI, reports) over bridge, flexure,
calibration and estimator."""

__version__ = "0.1.0"
