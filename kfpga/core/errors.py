"""The errors a user can cause: each is reported by the CLI in one line, with exit code 2."""

__all__ = ["ConfigError", "InputError", "UsageError", "PinError", "USER_ERRORS"]


class _OneLine(ValueError):
    """An error whose message is one line: a control character a user's file put into it (a key
    named with a newline) is shown escaped."""

    def __str__(self):
        text = super().__str__()
        return text if text.isprintable() else "".join(c if c.isprintable() else repr(c)[1:-1] for c in text)


class ConfigError(_OneLine):
    """A configuration value is invalid; the message names the field and the value."""


class InputError(_OneLine):
    """A user's input file is unusable; the message says where and why."""


class UsageError(ValueError):
    """A bad argument or combination of arguments."""


class PinError(ValueError):
    """The pin table does not fit the design; the message names the row or the port bit."""


#: What the CLI reports in one line with exit code 2.
USER_ERRORS = (ConfigError, InputError, UsageError, PinError)
