"""The errors a user can cause: each is reported by the CLI in one line, with exit code 2."""

__all__ = ["ConfigError", "InputError", "UsageError", "PinError", "USER_ERRORS"]


class ConfigError(ValueError):
    """A configuration value is invalid; the message names the field and the value."""


class InputError(ValueError):
    """A user's input file is unusable; the message says where and why."""


class UsageError(ValueError):
    """A bad argument or combination of arguments."""


class PinError(ValueError):
    """The pin table does not fit the design; the message names the row or the port bit."""


#: What the CLI reports in one line with exit code 2.
USER_ERRORS = (ConfigError, InputError, UsageError, PinError)
