"""What the commands print besides their report: progress on stderr, notes, JSON, the seed drawn."""

from __future__ import annotations

import json
import math
import secrets
import sys

import numpy as np


def progress_bar(quiet=False, **options):
    """A tqdm progress bar on stderr, shown only on a terminal (a log file or a CI run gets no
    frames) and never with ``quiet``."""
    from tqdm import tqdm

    return tqdm(file=sys.stderr, disable=True if quiet else None, **options)


def pick_seed(seed):
    return secrets.randbelow(2**31) if seed is None else seed


def emit_json(obj):
    def clean(value):
        if isinstance(value, float) and not math.isfinite(value):
            return None if math.isnan(value) else ("inf" if value > 0 else "-inf")
        if isinstance(value, dict):
            return {k: clean(v) for k, v in value.items()}
        if isinstance(value, list | tuple):
            return [clean(v) for v in value]
        if isinstance(value, np.integer | np.floating):
            return clean(value.item())
        return value

    print(json.dumps(clean(obj), indent=2))


def info(text):
    print(text, file=sys.stderr)
