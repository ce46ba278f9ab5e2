"""SIGINT and SIGTERM stop the whole `gpf` command: its child processes too (the simulator's
build, make, the compiler, the simulation, Yosys), which a signal sent to gpf's process alone
would leave running. The handler stops every descendant, then raises KeyboardInterrupt in the
main thread, so the outputs being written are abandoned (their temporary files removed) and
`gpf` exits with 128 + the signal's number.
"""

from __future__ import annotations

import contextlib
import os
import signal
from collections.abc import Iterator
from pathlib import Path


class Interrupted(KeyboardInterrupt):
    def __init__(self, signum: int):
        super().__init__(signal.Signals(signum).name)
        self.signum = signum


def descendants(pid: int) -> list[int]:
    """Every process below `pid`, children first (Linux /proc; none found elsewhere)."""
    found, todo = [], [pid]
    while todo:
        parent = todo.pop()
        for task in Path(f"/proc/{parent}/task").glob("*"):
            with contextlib.suppress(OSError, ValueError):
                for child in map(int, (task / "children").read_text().split()):
                    if child not in found:
                        found.append(child)
                        todo.append(child)
    return found


def stop_descendants(sig: int = signal.SIGTERM) -> list[int]:
    """Send `sig` to every descendant of this process; the pids it reached."""
    reached = []
    for pid in descendants(os.getpid()):
        with contextlib.suppress(ProcessLookupError, PermissionError):
            os.kill(pid, sig)
            reached.append(pid)
    return reached


def _handler(signum: int, frame: object) -> None:
    stop_descendants()
    raise Interrupted(signum)


@contextlib.contextmanager
def stop_all_on_signal() -> Iterator[None]:
    """While inside: SIGINT and SIGTERM stop the children and raise Interrupted. Only in the
    main thread (Python's rule); elsewhere it does nothing."""
    try:
        previous = {s: signal.signal(s, _handler) for s in (signal.SIGINT, signal.SIGTERM)}
    except ValueError:   # not the main thread
        yield
        return
    try:
        yield
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)
