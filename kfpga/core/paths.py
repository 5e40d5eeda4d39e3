"""Every file a command reads or writes is checked here, once, with one-line errors.

Readers accept UTF-8 with or without a byte-order mark (Excel's "CSV UTF-8" and Notepad write
one) and name the file and line of any undecodable byte. Writers refuse a directory where a
file is expected, a missing parent folder, an unwritable place, an output that is also an
input, and an extension the command cannot write.
"""

from __future__ import annotations

import os
from pathlib import Path

from kfpga.core.errors import InputError, UsageError

__all__ = ["read_text", "check_output_file", "check_output_dir"]


def read_text(path, *, what="file"):
    """The text of ``path`` (UTF-8, a BOM dropped); :class:`InputError` naming the problem."""
    path = Path(path)
    try:
        data = path.read_bytes()
    except FileNotFoundError:
        raise InputError(f"{path}: no such {what}") from None
    except IsADirectoryError:
        raise InputError(f"{path}: is a directory, not a {what}") from None
    except PermissionError:
        raise InputError(f"{path}: cannot read the {what} (permission denied)") from None
    except OSError as exc:
        raise InputError(f"{path}: cannot read the {what} ({exc.strerror})") from None
    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        line = data[: exc.start].count(b"\n") + 1
        raise InputError(f"{path}: line {line}: byte 0x{data[exc.start]:02x} is not UTF-8; save the {what} as UTF-8") from None
    return text


def check_output_file(path, *, option, inputs=(), extensions=None):
    """Check that ``path`` can be written as a file; returns it as a ``Path``.

    ``inputs`` are paths this command reads (an output must not overwrite one); ``extensions``
    the suffixes it can write (``None``: any).
    """
    path = Path(path)
    if path.is_dir():
        raise UsageError(f"{option} {path}: is a directory; give a file name")
    if extensions is not None and path.suffix.lower() not in extensions:
        raise UsageError(f"{option} {path}: the extension must be {' or '.join(extensions)}, not "
                         f"{path.suffix or 'none'!r}")
    parent = path.parent if str(path.parent) else Path(".")
    if not parent.exists():
        raise UsageError(f"{option} {path}: the folder {parent} does not exist")
    if not parent.is_dir():
        raise UsageError(f"{option} {path}: {parent} is a file, not a folder")
    if not os.access(parent, os.W_OK) or (path.exists() and not os.access(path, os.W_OK)):
        raise UsageError(f"{option} {path}: not writable")
    for source in inputs:
        if source is not None and path.exists() and Path(source).exists() and path.resolve() == Path(source).resolve():
            raise UsageError(f"{option} {path}: is also an input; write to another file")
    return path


def check_output_dir(path, *, option):
    """Check that ``path`` can be made (or is) a folder to write into; returns it."""
    path = Path(path)
    for parent in (path, *path.parents):
        if parent.exists():
            if not parent.is_dir():
                raise UsageError(f"{option} {path}: {parent} is a file, not a folder")
            if not os.access(parent, os.W_OK):
                raise UsageError(f"{option} {path}: {parent} is not writable")
            break
    return path
