"""Error types of clutch_model. The CLI catches ClutchSimError once and prints one line."""


class ClutchSimError(Exception):
    """Base of every error a user can cause with bad input."""


class ParamsError(ClutchSimError):
    """A clutch parameter file is missing, malformed or out of range."""


class DataError(ClutchSimError):
    """Measured data (bag, CSV) is missing, empty, truncated or inconsistent."""


class FitError(ClutchSimError):
    """An identification could not run on the given data."""
