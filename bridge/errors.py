"""Errors a user can fix: bad files, bad parameters; and the package's named warnings.

The CLI turns an `InputError` into exit code 2 and its message on one line of stderr, so the
message must name the file, line, column or field and say what is wrong.
"""


from userio.errors import InputError  # noqa: F401  (the project's one user-error type)


class BridgeWarning(UserWarning):
    """Base class of the bridge package's warnings (filter them with this class)."""


class StrainRangeWarning(BridgeWarning):
    """A gauge strain beyond the gauge's rated range (±3 % by default): results are extrapolated."""


class ADCSaturationWarning(BridgeWarning):
    """Samples clipped at the ADC's rails; their torque is returned as NaN, never as a number."""


class BridgeInverseWarning(BridgeWarning):
    """A bridge ratio outside the arrangement's physical range (inverse singular): NaN returned."""
