"""A whole-filter run's Python work in threads beside the simulation.

The simulator runs in cocotb's thread, without the GIL between triggers, so Python threads
work while it simulates:
ModelAhead: the fixed-point model's steps, ahead of the simulation (they depend on the model's
  own previous step only, never on the RTL's); step k's results with `get`, in order.
Checker: each step read and scored as soon as its result is out, while the simulation goes on
  to the next; the cocotb side only waits for each result and hands it over.
A failure in either thread is raised in the cocotb thread.
"""

from __future__ import annotations

import queue
import sys
import threading
from collections.abc import Callable, Iterator
from dataclasses import dataclass

import numpy as np

from gpf.model.fixed_gpf import FixedGPF, StepResult

CHUNK = 8        # steps of draws made at a time: the first step's expectation comes early
AHEAD = 16       # steps the thread may be ahead of the checks (bounds the memory held)
SWITCH_SECONDS = 1e-4   # Python's GIL hand-over interval while the thread runs (default 5 ms)


@dataclass
class Expected:
    res: StepResult
    cond: dict[str, np.ndarray]
    part: dict[str, np.ndarray]


def model_steps(gpf: FixedGPF, state: tuple, raw_inputs: list[dict], seed: int | None,
                expect: Callable[[StepResult], tuple[dict, dict]],
                corrupt: Callable[[np.ndarray], np.ndarray] | None,
                draw_chunks: list[np.ndarray]) -> Iterator[Expected]:
    """Steps 1..len(raw_inputs) of `gpf` from state (mu, chol, sigma), in order, with the GRNG
    model's draws after a load of `seed` (None: after reset), CHUNK steps of draws at a time
    (each chunk appended to `draw_chunks`; `corrupt` reorders it: the broken model)."""
    stream = gpf.draw_stream(seed)
    mu, chol, sigma = state
    steps = len(raw_inputs)
    for first in range(0, steps, CHUNK):
        draws = stream.next(min(CHUNK, steps - first))
        if corrupt:
            draws = corrupt(draws)
        draw_chunks.append(draws)
        for i, e in enumerate(draws):
            res = gpf.step(mu, chol, sigma, raw_inputs[first + i], e, keep_particles=True)
            mu, chol, sigma = res.mu, res.chol, res.sigma
            yield Expected(res, *expect(res))


class ModelAhead:
    """Steps 1..steps of `gpf` from (mu, chol, sigma) on `raw_inputs`, with the GRNG model's
    draws after a load of `seed` (None: after reset); `corrupt` reorders each chunk's draws
    (the deliberately broken model). `expect` turns a step's result into the taps' fields."""

    def __init__(self, gpf: FixedGPF, mu: np.ndarray, chol: np.ndarray, sigma: dict,
                 raw_inputs: list[dict], seed: int | None,
                 expect: Callable[[StepResult], tuple[dict, dict]],
                 corrupt: Callable[[np.ndarray], np.ndarray] | None = None):
        self.gpf, self.state, self.raw_inputs = gpf, (mu, chol, sigma), raw_inputs
        self.seed, self.expect, self.corrupt = seed, expect, corrupt
        self.draw_chunks: list[np.ndarray] = []
        self._queue: queue.Queue = queue.Queue(maxsize=AHEAD)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="model-ahead", daemon=True)
        # the simulator waits for the GIL whenever a trigger fires: hand it over quickly
        self._switch = sys.getswitchinterval()
        sys.setswitchinterval(SWITCH_SECONDS)
        self._thread.start()

    def _run(self) -> None:
        try:
            for expected in model_steps(self.gpf, self.state, self.raw_inputs, self.seed,
                                        self.expect, self.corrupt, self.draw_chunks):
                if not self._put(expected):
                    return
        except BaseException as exc:   # raised in the cocotb thread by get()
            self._put(exc)

    def _put(self, item: object) -> bool:
        while not self._stop.is_set():
            try:
                self._queue.put(item, timeout=0.1)
                return True
            except queue.Full:
                continue
        return False

    def get(self) -> Expected:
        """The next step's results (waiting for the thread if it is behind)."""
        item = self._queue.get()
        if isinstance(item, BaseException):
            raise item
        return item

    def draws(self) -> np.ndarray:
        """Every step's draws (steps, N, D), once every step was taken with get()."""
        self._thread.join()
        return np.concatenate(self.draw_chunks)

    def stop(self) -> None:
        """End the thread (early, in a run that failed)."""
        self._stop.set()
        sys.setswitchinterval(self._switch)


class Checker:
    """Runs check(k) in a thread for each k submitted, in order (see the module's docstring)."""

    def __init__(self, check: Callable[[int], None]):
        self.check = check
        self.error: BaseException | None = None
        self._todo: queue.Queue = queue.Queue()
        self._thread = threading.Thread(target=self._run, name="checker", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while (k := self._todo.get()) is not None:
            try:
                self.check(k)
            except BaseException as exc:   # raised in the cocotb thread
                self.error = exc
                return

    def submit(self, k: int) -> None:
        """Check step k (its beats are out); raise what an earlier check raised."""
        self._raise()
        self._todo.put(k)

    def finish(self) -> None:
        """Wait for every check submitted."""
        self._todo.put(None)
        self._thread.join()
        self._raise()

    def stop(self) -> None:
        """No more checks (a run that failed): the thread ends after the one it is on."""
        self._todo.put(None)

    def _raise(self) -> None:
        if self.error is not None:
            raise self.error
