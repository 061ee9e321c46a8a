"""Reading a user's input file with a size bound (issue 61): ``/dev/zero`` or a multi-gigabyte file given
as a JSON mapping, a stream script or a rig is a one-line error after at most ``max_bytes + 1`` bytes read,
never a read that grows memory without end.

The bounds are `kinema.limits.MAX_JSON_BYTES` for small JSON/JSON-lines/CSV inputs (mappings, overrides,
timelines, constraints, scripts, jobs files) and `kinema.limits.MAX_ASSET_BYTES` for rig and motion files
(BVH, glTF/GLB and their buffers).
"""

from __future__ import annotations

import gzip
import io
import json
import zlib
from pathlib import Path
from typing import Any

from kinema.errors import KinemaError
from kinema.limits import MAX_JSON_BYTES


def check_input_file(path: str | Path, what: str) -> Path:
    """``path`` as a Path, checked before any work: a missing path, a folder, or something that is not a
    regular file (a device such as ``/dev/zero``, a pipe) is a one-line `KinemaError` naming ``what``."""
    path = Path(path)
    if path.is_dir():
        raise KinemaError(f"{path}: is a folder, not a {what}")
    if not path.exists():
        raise KinemaError(f"{path}: no such {what}")
    if not path.is_file():
        raise KinemaError(f"{path}: is not a regular file (a device or a pipe?), not a {what}")
    return path


def read_bytes_bounded(
    path: str | Path, what: str, max_bytes: int = MAX_JSON_BYTES, error: type[KinemaError] = KinemaError
) -> bytes:
    """The bytes of ``path``; a missing file, a folder, an unreadable file or one larger than ``max_bytes``
    is a one-line ``error`` (a `KinemaError`) that names the file and ``what`` it should have been. A
    ``.gz`` file is gunzipped, its unpacked size bound the same way."""
    path = Path(path)
    try:
        with path.open("rb") as fh:
            data = fh.read(max_bytes + 1)
        if path.name.lower().endswith(".gz") and len(data) <= max_bytes:
            with gzip.GzipFile(fileobj=io.BytesIO(data)) as unpacked:
                data = unpacked.read(max_bytes + 1)
    except FileNotFoundError:
        raise error(f"{path}: no such {what}") from None
    except IsADirectoryError:
        raise error(f"{path}: is a folder, not a {what}") from None
    except (EOFError, zlib.error, gzip.BadGzipFile) as err:
        raise error(f"{path}: not a readable gzip file ({err})") from None
    except OSError as err:
        raise error(f"{path}: cannot read the {what} ({err.strerror or err})") from None
    if len(data) > max_bytes:
        raise error(f"{path}: larger than {max_bytes} bytes, too large for a {what}")
    return data


def read_text_bounded(
    path: str | Path, what: str, max_bytes: int = MAX_JSON_BYTES, error: type[KinemaError] = KinemaError
) -> str:
    """The UTF-8 text of ``path``, read as `read_bytes_bounded`; bytes that are not UTF-8 are an error."""
    data = read_bytes_bounded(path, what, max_bytes, error)
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as err:
        raise error(f"{path}: the {what} is not UTF-8 text (byte {err.start})") from None


def read_json_bounded(
    path: str | Path, what: str, max_bytes: int = MAX_JSON_BYTES, error: type[KinemaError] = KinemaError
) -> Any:
    """The parsed JSON of ``path``, read as `read_text_bounded`; a syntax error names its line."""
    text = read_text_bounded(path, what, max_bytes, error)
    try:
        return json.loads(text)
    except json.JSONDecodeError as err:
        raise error(f"{path}:{err.lineno}: not valid JSON ({err.msg}; a {what} is expected)") from None
    except RecursionError:
        raise error(f"{path}: JSON nested too deeply to read (not a {what})") from None
