"""Every file a command reads or writes is checked here, once, with one-line errors.

Readers accept UTF-8 with or without a byte-order mark (Excel's "CSV UTF-8" and Notepad write
one) and name the file and line of any undecodable byte. Writers refuse, before the work
starts, a directory where a file is expected and the reverse, a missing parent folder, a place
that cannot be written (tried by writing a probe file there: permission bits say nothing to
root, nor about /proc or a read-only mount), an output that is also an input, and an extension
the command cannot write. Outputs appear whole or not at all: :func:`atomic_file` and
:func:`atomic_dir` write under a temporary name beside the target and rename it when complete.
"""

from __future__ import annotations

import contextlib
import errno
import os
import shutil
import tempfile
from pathlib import Path

from kfpga.core.errors import InputError, UsageError

__all__ = ["read_text", "check_output_file", "check_output_dir", "atomic_file", "atomic_dir", "write_text"]

#: The prefix of the temporary names outputs are written under.
TEMP_PREFIX = ".kfpga-tmp-"


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
    why = _cannot_write(parent)
    if why:
        raise UsageError(f"{option} {path}: cannot write into {parent} ({why})")
    if path.exists() and not os.access(path, os.W_OK):
        raise UsageError(f"{option} {path}: not writable")
    for source in inputs:
        if source is not None and path.exists() and Path(source).exists() and path.resolve() == Path(source).resolve():
            raise UsageError(f"{option} {path}: is also an input; write to another file")
    return path


def _cannot_write(folder):
    """Why a new file cannot be written into ``folder`` (``None``: it can), found by writing and
    removing a probe file."""
    try:
        fd, name = tempfile.mkstemp(prefix=TEMP_PREFIX, dir=folder)
    except OSError as exc:
        return "it takes no new files" if exc.errno == errno.ENOENT else (exc.strerror or str(exc)).lower()
    os.close(fd)
    os.unlink(name)
    return None


def check_output_dir(path, *, option, marker=None):
    """Check that ``path`` can be made (or is) a folder to write into; returns it.

    ``marker``: the file this command writes into its folder (``manifest.json``); an existing
    folder that holds other files but not the marker was not written by it, and is refused
    rather than replaced (:func:`atomic_dir` replaces the folder whole).
    """
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise UsageError(f"{option} {path}: is a file; give a folder")
    if marker is not None and path.is_dir() and any(path.iterdir()) and not (path / marker).is_file():
        raise UsageError(f"{option} {path}: the folder holds files this command did not write (no {marker}); "
                         "give a new or empty folder")
    for parent in (path, *path.parents):
        if parent.exists():
            if not parent.is_dir():
                raise UsageError(f"{option} {path}: {parent} is a file, not a folder")
            why = _cannot_write(parent) or (_cannot_write(parent.parent) if parent == path else None)
            if why:
                raise UsageError(f"{option} {path}: cannot write into {parent} ({why})")
            break
    return path


def _temp_name(path):
    """A temporary name beside ``path``, with its suffix (a plot's format follows it)."""
    return path.with_name(f"{TEMP_PREFIX}{os.getpid()}-{path.name}")


def _made_parents(path):
    """Create ``path``'s missing parent folders; returns those made, deepest first."""
    made = []
    for parent in path.parents:
        if parent.exists():
            break
        made.append(parent)
    for parent in reversed(made):
        parent.mkdir()
    return made


def _remove_made(made):
    for folder in made:
        with contextlib.suppress(OSError):
            folder.rmdir()


@contextlib.contextmanager
def atomic_file(path):
    """Yield a temporary path beside ``path`` to write; it becomes ``path`` when the block ends,
    and is removed (with any parent folder made for it) when the block raises or is interrupted."""
    path = Path(path)
    made = _made_parents(path)
    temp = _temp_name(path)
    try:
        yield temp
        os.replace(temp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            temp.unlink()
        _remove_made(made)
        raise


@contextlib.contextmanager
def atomic_dir(path):
    """Yield a new temporary folder beside ``path`` to write; when the block ends it replaces
    ``path`` whole (a folder written before is removed, so no stale file stays); when the block
    raises or is interrupted it is removed, and ``path`` is as it was."""
    path = Path(path)
    made = _made_parents(path)
    temp = _temp_name(path)
    shutil.rmtree(temp, ignore_errors=True)
    try:
        temp.mkdir()
        yield temp
        if path.exists():
            old = path.with_name(f"{TEMP_PREFIX}{os.getpid()}-old-{path.name}")
            os.replace(path, old)
            os.replace(temp, path)
            shutil.rmtree(old, ignore_errors=True)
        else:
            os.replace(temp, path)
    except BaseException:
        shutil.rmtree(temp, ignore_errors=True)
        _remove_made(made)
        raise


def write_text(path, text):
    """Write ``text`` to ``path`` whole or not at all (:func:`atomic_file`)."""
    with atomic_file(path) as temp:
        temp.write_text(text)
