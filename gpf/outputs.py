"""Every file gpf writes: never over one of its inputs, never half-written, strict JSON.

check_outputs(outputs, inputs): refuse an output that is (or lies inside) an input, or that
    another output also writes; paths are compared resolved (symlinks, `..`).
atomic_write_text / atomic_write_bytes / atomic_path: write a temporary file in the target's
    folder and rename it into place only when it is complete; on a failure or an interrupt
    (KeyboardInterrupt too) the temporary file is removed and the target keeps what it held.
    An OSError names the target, not the temporary file.
json_text / write_json: JSON without NaN or Infinity (a missing value is null).
fmt(x, spec): a number for a summary, "n/a" for a quantity that could not be computed.
"""

from __future__ import annotations

import json
import math
import os
import secrets
import stat
from collections.abc import Iterable, Iterator
from contextlib import contextmanager, suppress
from pathlib import Path
from typing import Any

NA = "n/a"


class OutputError(ValueError):
    """An output that would overwrite an input; str() is the one line for the user."""


def _real(path: str | Path) -> Path:
    return Path(os.path.realpath(path))


def check_outputs(outputs: Iterable[tuple[str, str | Path | None]],
                  inputs: Iterable[tuple[str, str | Path | None]]) -> None:
    """Raise OutputError, naming the option, the path and the input, when an output (option,
    path) is an input (what, path) or lies inside one, or when two options write one file
    (or one inside the other).
    Pass every file a command will write (a folder's files, not just the folder)."""
    ins = [(what, Path(p), _real(p)) for what, p in inputs if p is not None]
    seen: dict[Path, tuple[str, Path]] = {}
    for option, path in outputs:
        if path is None:
            continue
        real = _real(path)
        for what, given, known in ins:
            if real == known or real.is_relative_to(known):
                raise OutputError(f"{option} {path}: would overwrite {what} {given}; "
                                  f"choose another {option}")
        for known, (other, given) in seen.items():
            if other == option:
                continue
            if real == known:
                also = "" if str(given) == str(path) else f" ({given})"
                raise OutputError(f"{option} {path}: is also the file {other} writes{also}; "
                                  f"choose another {option}")
            if real.is_relative_to(known) or known.is_relative_to(real):
                raise OutputError(f"{option} {path}: {other} writes {given}, a file where "
                                  f"this needs a folder or the other way round; choose "
                                  f"another {option}")
        seen[real] = (option, Path(path))


def _temporary(target: Path) -> Path:
    """A fresh hidden name in the target's folder, keeping its suffix (matplotlib and numpy
    choose the format by it)."""
    return target.with_name(f".{target.stem}.{os.getpid()}.{secrets.token_hex(4)}.tmp"
                            f"{target.suffix}")


def _unlink(path: Path) -> None:
    with suppress(OSError):
        path.unlink(missing_ok=True)


@contextmanager
def atomic_path(path: str | Path) -> Iterator[Path]:
    """A temporary path for a writer that takes a path (savefig, numpy.save); renamed onto
    `path` when the block ends without an error, removed otherwise."""
    given = Path(path)
    target = _real(given) if given.is_symlink() else given   # a link keeps pointing there
    try:
        target.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise OSError(exc.errno, exc.strerror or str(exc), str(given)) from None
    tmp = _temporary(target)
    try:
        yield tmp
        try:
            mode = stat.S_IMODE(target.stat().st_mode)
        except OSError:
            mode = None
        if mode is not None:
            os.chmod(tmp, mode)
        os.replace(tmp, target)
    except OSError as exc:
        _unlink(tmp)
        raise OSError(exc.errno, exc.strerror or str(exc), str(given)) from None
    except BaseException:        # an error in the writer, KeyboardInterrupt, SIGTERM
        _unlink(tmp)
        raise


def atomic_write_bytes(path: str | Path, data: bytes) -> None:
    with atomic_path(path) as tmp, open(tmp, "xb") as f:
        f.write(data)


def atomic_write_text(path: str | Path, text: str) -> None:
    with atomic_path(path) as tmp, open(tmp, "x", encoding="utf-8") as f:
        f.write(text)


def finite(obj: Any) -> Any:
    """`obj` with every NaN or infinite float (numpy's too) as None, tuples and arrays as
    lists: what strict JSON can hold."""
    if isinstance(obj, dict):
        return {k: finite(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [finite(v) for v in obj]
    if hasattr(obj, "tolist") and not isinstance(obj, str | bytes):   # numpy arrays, scalars
        return finite(obj.tolist())
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    return obj


def json_text(obj: Any, indent: int | None = 1, sort_keys: bool = False) -> str:
    """Strict JSON: non-finite floats become null first; anything else that is not JSON
    fails here (allow_nan=False), not in the reader."""
    return json.dumps(finite(obj), indent=indent, sort_keys=sort_keys, allow_nan=False) + "\n"


def write_json(path: str | Path, obj: Any, indent: int | None = 1,
               sort_keys: bool = False) -> None:
    atomic_write_text(path, json_text(obj, indent, sort_keys))


def fmt(x: Any, spec: str = ".4g") -> str:
    """`x` formatted, or "n/a" when it is missing or not finite."""
    if x is None or (isinstance(x, float) and not math.isfinite(x)):
        return NA
    return format(x, spec)
