"""Reading users' sample files and writing filter outputs, with errors that name the line."""

from __future__ import annotations

import csv
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from kfpga.core.codes import CODE_MAX, CODE_MIN
from kfpga.core.errors import InputError
from kfpga.core.paths import read_text

__all__ = ["InputError", "Samples", "Table", "read_table", "read_samples", "read_header", "write_columns", "read_series"]


@dataclass
class Samples:
    """Samples read from a CSV file."""

    codes: dict  # {column: int64 ADC codes}
    truth: np.ndarray | None  # float, when the file has a ``truth`` column
    clipped: int  # values saturated because of ``clip=True``
    path: str
    missing: np.ndarray | None = None  # per row: no measurement (every code cell empty), when allowed

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


#: The separators a table may use, in the order they are preferred on a tie.
SEPARATORS = (",", ";", "\t")


@dataclass
class Table:
    """The cells of a CSV file as people write them: ``names`` (from the header line, or made
    up when the first line is numbers), and ``rows`` of ``(line number, cells)``."""

    names: list
    rows: list
    header: bool
    separator: str
    line: int = 1  # of the header (comment lines may come first)


def read_table(path, *, single="y", unnamed=False, blank_rows=False):
    """Read ``path`` as a table: a UTF-8 BOM, ``#`` comment lines and blank lines at the end are
    dropped; the separator is a comma, a semicolon or a tab (the one the first line uses most);
    the first line is a header unless all its cells are numbers. A file of one column with no
    header is the column ``single``; several columns with no header are refused, or with
    ``unnamed`` named ``column 1``, ``column 2``, ... A blank line among the rows is refused
    (every row is a sample), naming its line; with ``blank_rows`` it is a row of empty cells (a
    sample with no measurement in a one-column file)."""
    path = Path(path)
    text = read_text(path, what="file")
    lines = [(n, line) for n, line in enumerate(text.splitlines(), start=1) if not line.lstrip().startswith("#")]
    while lines and not lines[-1][1].strip():
        lines.pop()
    if not lines:
        raise InputError(f"{path}: the file is empty (expected a header line and one row per sample)")
    first = lines[0][1]
    separator = max(SEPARATORS, key=lambda sep: (first.count(sep), -SEPARATORS.index(sep)))
    cells = []
    for n, line in lines:  # a line is a row: a quote left open does not swallow the lines after it
        try:
            cells.append(next(csv.reader([line], delimiter=separator), []))
        except csv.Error as exc:
            raise InputError(f"{path}: line {n}: not readable as CSV ({exc})") from None
    names = [h.strip() for h in cells[0]]
    header = not all(_is_number(name) for name in names)
    if not header and unnamed:
        names = [f"column {k + 1}" for k in range(len(names))]
    elif not header:
        if len(names) != 1:
            raise InputError(f"{path}: line {lines[0][0]}: no header line; name the {len(names)} columns in a first "
                             "line (for example y,truth)")
        names = [single]
    rows = list(zip([n for n, _ in lines], cells, strict=True))[1 if header else 0:]
    for n, row in rows:
        if not blank_rows and not any(cell.strip() for cell in row):
            raise InputError(f"{path}: line {n}: a blank line; every row is a sample (delete the line, or give it a "
                             "value)")
    return Table(names, rows, header, separator, lines[0][0])


def read_samples(path, *, clip=False, column="y", columns=None, bits=16, missing=False):
    """Read the ``y`` column (signed 16-bit ADC codes, or ``bits``-bit integers), or each of
    ``columns``, and ``truth`` if present.

    The file is read by :func:`read_table` (comments, separators, a headerless single column).
    Every problem raises :class:`InputError` with the file and line: no such file, a folder,
    bytes that are not UTF-8, no rows, a missing code column or one named twice, a blank line
    among the rows, a cell that is empty, not a number, NaN, not an integer, or outside
    [-32768, 32767] (unless ``clip``, which saturates such values and counts them).

    With ``missing``, a row whose code cells are all empty (a blank line in a one-column file) is
    a sample with no measurement: its codes read 0 and :attr:`Samples.missing` marks it; a row
    with some of them empty is refused.
    """
    path = Path(path)
    wanted = list(columns) if columns is not None else [column]
    table = read_table(path, single=wanted[0], blank_rows=missing)
    names = table.names
    codes, truths, clipped = {c: [] for c in wanted}, [], 0
    for name in (*wanted, "truth"):
        if names.count(name) > 1:
            raise InputError(f"{path}: line {table.line}: the header names column {name!r} twice")
    absent = [c for c in wanted if c not in names]
    if absent:
        need = f"no column named {absent[0]!r}" if len(absent) == 1 else \
            f"no columns named {' and '.join(repr(c) for c in absent)}"
        raise InputError(f"{path}: line {table.line}: {need} (the header has: {', '.join(names) or 'nothing'})")
    index = {c: names.index(c) for c in wanted}
    it = names.index("truth") if "truth" in names else None
    lost = []
    for line, row in table.rows:
        where = f"{path}: line {line}"
        gone = missing and _lost(row, index, where)
        lost.append(gone)
        for name, iy in index.items():
            value, out = (0, 0) if gone else _code(row, iy, name, where, bits, clip)
            clipped += out
            codes[name].append(value)
        if it is not None:
            if it >= len(row) or not row[it].strip():
                raise InputError(f"{where}: no value in column 'truth'")
            truths.append(_number(row[it], where, "truth"))
    if not codes[wanted[0]]:
        raise InputError(f"{path}: no data rows after the header")
    truth = np.array(truths, dtype=np.float64) if it is not None else None
    return Samples({c: np.array(v, dtype=np.int64) for c, v in codes.items()}, truth, clipped, str(path),
                   np.array(lost, dtype=bool) if missing else None)


def _lost(row, index, where):
    """Whether ``row`` is a sample with no measurement: every code cell empty (some of them: refused)."""
    empty = [name for name, iy in index.items() if iy >= len(row) or not row[iy].strip()]
    if empty and len(empty) != len(index):
        given = [name for name in index if name not in empty]
        raise InputError(f"{where}: {', '.join(given)} given but {', '.join(empty)} empty: a sample with no "
                         "measurement leaves every input cell empty")
    return bool(empty)


def _code(row, iy, name, where, bits, clip):
    """The integer in cell ``iy`` of ``row``, in the signed ``bits``-bit range (saturated when
    ``clip``), and 1 if it was saturated, else 0."""
    low, high = (CODE_MIN, CODE_MAX) if bits == 16 else (-(1 << (bits - 1)), (1 << (bits - 1)) - 1)
    if iy >= len(row) or not row[iy].strip():
        raise InputError(f"{where}: no value in column {name!r}")
    value = _number(row[iy], where, name)
    if value != int(value):
        raise InputError(f"{where}: {name} = {row[iy].strip()} is not an integer "
                         + ("ADC code" if bits == 16 else "sample"))
    if low <= value <= high:
        return int(value), 0
    if not clip:
        raise InputError(f"{where}: {name} = {row[iy].strip()} is outside the signed {bits}-bit range "
                         f"[{low}, {high}] (use --clip to saturate such values)")
    return int(min(max(value, low), high)), 1


def read_header(path, *, single="y"):
    """The column names of a CSV file (BOM dropped, cells stripped; ``single`` for a headerless
    single column)."""
    return read_table(path, single=single).names


def write_columns(path, columns):
    """Write ``{name: array}`` as CSV, one row per element (integers stay integers)."""
    from kfpga.core.paths import atomic_file

    names = list(columns)
    arrays = [np.asarray(columns[n]) for n in names]
    with atomic_file(path) as temp, temp.open("w", newline="") as handle:
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
    """A series of real numbers from one column of a CSV file (:func:`read_table`): the only
    column, or the one named ``column``, or the last one. Every problem raises
    :class:`InputError` with the file and line: no rows, a missing column, a cell that is empty,
    not a number or not finite."""
    table = read_table(path, single="column 1", unnamed=True)
    names = table.names
    if column is not None and column not in names:
        raise InputError(f"{path}: line {table.line}: no column named {column!r} (the header has: {', '.join(names)})")
    k = names.index(column) if column is not None else len(names) - 1
    values = [_number(row[k] if k < len(row) else "", f"{path}: line {n}", names[k]) for n, row in table.rows]
    if not values:
        raise InputError(f"{path}: no rows after the header")
    return np.array(values)
