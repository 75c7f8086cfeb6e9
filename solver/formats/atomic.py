"""Writing a file through a temporary name: the file at the final path is either the old one or the whole
new one, and a failed write leaves no temporary file behind (every writer of bundles, reports, PNGs and
point caches)."""
import contextlib
import os

from ..errors import ArticulaInputError


@contextlib.contextmanager
def written_through(path: str, tmp: str, what: str):
    """Write ``tmp`` inside the block; it is renamed onto ``path`` when the block ends.  On any failure
    ``tmp`` is removed; an ``OSError`` (a folder at ``path``, no permission, a full disk) becomes
    :class:`ArticulaInputError` ``"<path>: cannot write <what> (<reason>)"``."""
    try:
        yield tmp
        os.replace(tmp, path)
    except BaseException as exc:
        if os.path.isfile(tmp):
            os.remove(tmp)
        if isinstance(exc, OSError):
            raise ArticulaInputError(f"{path}: cannot write {what} ({exc.strerror or exc})") from None
        raise
