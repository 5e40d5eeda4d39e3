"""Reading users' sample files and writing filter outputs, with errors that name the line."""

from __future__ import annotations

import csv
import io
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from kfpga.core.ads8364 import CODE_MAX, CODE_MIN
from kfpga.core.errors import InputError
from kfpga.core.paths import read_text

__all__ = ["InputError", "Samples", "read_samples", "read_header", "write_columns", "read_series"]


@dataclass
class Samples:
    """Samples read from a CSV file."""

    codes: dict  # {column: int64 ADC codes}
    truth: np.ndarray | None  # float, when the file has a ``truth`` column
    clipped: int  # values saturated because of ``clip=True``
    path: str

    @property
    def y(self):
        """The codes: one array for one column, else ``{column: array}`` (a filter's inputs)."""
        return next(iter(self.codes.values())) if len(self.codes) == 1 else dict(self.codes)

    def __len__(self):
        return len(next(iter(self.codes.values())))


def _number(text, where, column):
    try:
        value = float(text)
    except ValueError:
        raise InputError(f"{where}: {column} = {text.strip()!r} is not a number") from None
    if math.isnan(value):
        raise InputError(f"{where}: {column} is NaN")
    if math.isinf(value):
        raise InputError(f"{where}: {column} is infinite")
    return value


def read_samples(path, *, clip=False, column="y", columns=None):
    """Read the ``y`` column (signed 16-bit ADC codes), or each of ``columns``, and ``truth`` if present.

    Every problem raises :class:`InputError` with the file and line: no such file, a folder,
    bytes that are not UTF-8 (a byte-order mark is fine), no rows, a missing code column or one
    named twice, a blank line (every row is a sample: one output row per input row), a cell that
    is empty, not a number, NaN, not an integer, or outside [-32768, 32767] (unless ``clip``,
    which saturates such values and counts them).
    """
    path = Path(path)
    wanted = list(columns) if columns is not None else [column]
    text = read_text(path, what="file")
    reader = csv.reader(io.StringIO(text, newline=""))
    codes, truths, clipped = {c: [] for c in wanted}, [], 0
    try:
        header = next(reader, None)
    except csv.Error as exc:
        raise InputError(f"{path}: not a readable CSV file ({exc})") from None
    expected = " and ".join(repr(c) for c in wanted)
    if header is None:
        raise InputError(f"{path}: the file is empty (expected a header line with the column(s) {expected})")
    names = [h.strip() for h in header]
    for name in (*wanted, "truth"):
        if names.count(name) > 1:
            raise InputError(f"{path}: line 1: the header names column {name!r} twice")
    missing = [c for c in wanted if c not in names]
    if missing:
        need = f"no column named {missing[0]!r}" if len(missing) == 1 else \
            f"no columns named {' and '.join(repr(c) for c in missing)}"
        raise InputError(f"{path}: line 1: {need} (the header has: {', '.join(names) or 'nothing'})")
    index = {c: names.index(c) for c in wanted}
    it = names.index("truth") if "truth" in names else None
    try:
        for row in reader:
            where = f"{path}: line {reader.line_num}"
            if not any(cell.strip() for cell in row):
                raise InputError(f"{where}: a blank line; every row is a sample (delete the line, or give it a value)")
            for name, iy in index.items():
                if iy >= len(row) or not row[iy].strip():
                    raise InputError(f"{where}: no value in column {name!r}")
                value = _number(row[iy], where, name)
                if value != int(value):
                    raise InputError(f"{where}: {name} = {row[iy].strip()} is not an integer ADC code")
                if not CODE_MIN <= value <= CODE_MAX:
                    if not clip:
                        raise InputError(
                            f"{where}: {name} = {row[iy].strip()} is outside the signed 16-bit range "
                            f"[{CODE_MIN}, {CODE_MAX}] (use --clip to saturate such values)"
                        )
                    value = min(max(value, CODE_MIN), CODE_MAX)
                    clipped += 1
                codes[name].append(int(value))
            if it is not None:
                if it >= len(row) or not row[it].strip():
                    raise InputError(f"{where}: no value in column 'truth'")
                truths.append(_number(row[it], where, "truth"))
    except csv.Error as exc:
        raise InputError(f"{path}: line {reader.line_num}: not readable as CSV ({exc})") from None
    if not codes[wanted[0]]:
        raise InputError(f"{path}: no data rows after the header")
    truth = np.array(truths, dtype=np.float64) if it is not None else None
    return Samples({c: np.array(v, dtype=np.int64) for c, v in codes.items()}, truth, clipped, str(path))


def read_header(path):
    """The column names of a CSV file (BOM dropped, cells stripped)."""
    text = read_text(path, what="file")
    return [h.strip() for h in next(csv.reader(io.StringIO(text, newline="")), [])]


def write_columns(path, columns):
    """Write ``{name: array}`` as CSV, one row per element (integers stay integers)."""
    path = Path(path)
    names = list(columns)
    arrays = [np.asarray(columns[n]) for n in names]
    with path.open("w", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow(names)
        cells = [a.astype(int).tolist() if a.dtype.kind == "b" else a.tolist() for a in arrays]
        writer.writerows(zip(*cells, strict=True))


def _is_number(text):
    try:
        float(text)
    except ValueError:
        return False
    return True


def read_series(path, *, column=None):
    """A series of real numbers from one column of a CSV file (lines starting with ``#`` are
    comments): the only column, or the one named ``column``, or the last one. The first line is
    a header unless all its cells are numbers. Every problem
    raises :class:`InputError` with the file and line: no rows, a missing column, a cell that
    is empty, not a number or not finite."""
    path = Path(path)
    text = read_text(path, what="file")
    lines = [(n, line) for n, line in enumerate(text.splitlines(), start=1) if not line.lstrip().startswith("#")]
    if not lines:
        raise InputError(f"{path}: the file is empty (expected one number per row, under an optional header line)")
    rows = list(csv.reader([line for _, line in lines]))
    names = [h.strip() for h in rows[0]]
    # no header when the first line is a row of numbers: it is a sample, not names
    first = 0 if all(_is_number(name) for name in names) else 1
    if first == 0:
        names = [f"column {k + 1}" for k in range(len(names))]
    if column is not None and column not in names:
        raise InputError(f"{path}: line {lines[0][0]}: no column named {column!r} (the header has: {', '.join(names)})")
    k = names.index(column) if column is not None else len(names) - 1
    values = [_number(row[k] if k < len(row) else "", f"{path}: line {n}", names[k])
              for (n, _), row in zip(lines[first:], rows[first:], strict=True)]
    if not values:
        raise InputError(f"{path}: no rows after the header")
    return np.array(values)
