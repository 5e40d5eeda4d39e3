"""matplotlib set up once for files: the Agg backend, no display (a server, CI, a terminal)."""

__all__ = ["pyplot"]


def pyplot():
    """matplotlib's pyplot on the Agg backend (files, no display)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt
