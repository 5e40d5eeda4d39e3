"""matplotlib set up once for files: the Agg backend, no display (a server, CI, a terminal)."""

from pathlib import Path

__all__ = ["pyplot", "save_figure"]


def pyplot():
    """matplotlib's pyplot on the Agg backend (files, no display)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def save_figure(fig, path, *, dpi=110):
    """Write ``fig`` to ``path`` whole or not at all (under a temporary name, renamed when
    complete), and close it."""
    from kfpga.core.paths import atomic_file

    try:
        with atomic_file(path) as temp:
            fig.savefig(temp, dpi=dpi, format=Path(path).suffix.lstrip(".").lower() or None)
    finally:
        pyplot().close(fig)
