"""What the registry is meant to hold, written here by hand (not read from the registry), so
that the tests of its messages fail when a filter goes missing or comes in unannounced."""

#: The registered filters, in registry order.
FILTERS = ("kalman2", "alphabeta", "kalman", "lsfront", "roll", "tukey53h")
#: As the error messages list them.
REGISTERED = ", ".join(FILTERS)
