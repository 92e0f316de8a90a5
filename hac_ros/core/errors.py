"""Exception types of the core. Catch :class:`HacError` for anything the package raises on
purpose."""


class HacError(Exception):
    """Base class of every error raised on purpose by hac_ros."""


class ParameterError(HacError, ValueError):
    """A parameter value is invalid; the message names the parameter and the reason."""


class InputError(HacError, ValueError):
    """An input array has the wrong shape or content (the message says which and why)."""
