"""Files yarnfit writes: checked before any computation, written whole or not at all.

A fit runs for minutes and a catalogue for hours, so an output that cannot be written must fail
before the work starts (:func:`check_writable`), and an interrupted or failed run must leave no
half-written file behind (:func:`write_atomically`: a temporary file in the same directory, then
an atomic rename over the target).
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

__all__ = ["check_writable", "write_atomically"]

# The process's umask, read once (os.umask can only be read by setting it): mkstemp creates files
# readable by their owner only, and a written output should get the mode open() would give it.
_UMASK = os.umask(0o022)
os.umask(_UMASK)


def check_writable(path: str | os.PathLike, what: str, directory: bool = False) -> Path:
    """Check that ``path`` can be written (created, or replaced if it exists), creating no file.

    Args:
        path: the output file, or with ``directory`` an output directory (it may exist).
        what: what the output is, for the message (``"material file"``, ``"--rerun recording"``).
        directory: ``path`` is a directory that will hold outputs.

    Returns:
        ``path`` as a :class:`~pathlib.Path`.

    Raises:
        OSError: one line naming ``path`` and the reason: a directory where a file is wanted (or
            a file where a directory is), or a folder that does not exist and cannot be created,
            or one the user may not write into.
    """
    path = Path(path)
    if directory:
        if path.exists() and not path.is_dir():
            raise OSError(f"{path}: cannot write the {what}: it is a file, not a directory")
        folder = path
    else:
        if path.is_dir():
            raise OSError(f"{path}: cannot write the {what}: it is a directory")
        if path.exists() and not os.access(path, os.W_OK):
            raise OSError(f"{path}: cannot write the {what}: permission denied")
        folder = path.parent
    # The nearest existing ancestor must be a writable directory: that is where the missing ones
    # (created on writing) would go.
    existing = folder if str(folder) else Path(".")
    while not existing.exists():
        existing = existing.parent
    if not existing.is_dir():
        raise OSError(f"{path}: cannot write the {what}: {existing} is not a directory")
    if not os.access(existing, os.W_OK | os.X_OK):
        raise OSError(f"{path}: cannot write the {what}: {existing} is not writable")
    # os.access answers for permissions only; a read-only file system says no only when written.
    try:
        probe = tempfile.NamedTemporaryFile(dir=existing, prefix=".yarnfit-probe-", delete=True)
    except OSError as error:
        raise OSError(f"{path}: cannot write the {what}: {error.strerror or error}") from None
    probe.close()
    return path


def write_atomically(path: str | os.PathLike, data: str | bytes) -> Path:
    """Write ``data`` (text as UTF-8) to ``path`` whole or not at all (directories created): a
    temporary file beside it, flushed to disk, then renamed over ``path``. Returns ``path``."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    payload = data.encode("utf-8") if isinstance(data, str) else data
    handle, temporary = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".part")
    try:
        with os.fdopen(handle, "wb") as f:
            f.write(payload)
            f.flush()
            os.fsync(f.fileno())
            os.fchmod(f.fileno(), 0o666 & ~_UMASK)
        os.replace(temporary, path)
    except BaseException:
        # Interrupted or failed: the target keeps its old contents (or stays absent).
        try:
            os.unlink(temporary)
        except FileNotFoundError:
            pass
        raise
    return path
