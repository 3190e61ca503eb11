"""The user-error types of every package, gathered for the CLI (exit code 2, one line)."""

from bridge.errors import InputError as BridgeInputError
from calibration.errors import InputError as CalibrationInputError
from estimator.errors import InputError as EstimatorInputError
from flexure.errors import InputError as FlexureInputError


class InputError(ValueError):
    """Bad user input met by the composition layer (scene files, CLI arguments)."""


USER_ERRORS = (
    InputError,
    BridgeInputError,
    CalibrationInputError,
    EstimatorInputError,
    FlexureInputError,
    FileNotFoundError,
    IsADirectoryError,
    NotADirectoryError,
    PermissionError,
)
