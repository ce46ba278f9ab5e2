"""The fixed-point model of a whole-filter run, computed in a thread ahead of the simulation.

The model's steps depend on the model's own previous step only, never on the RTL's, so they
can run while the simulator does: the cocotb thread gives the simulator the GIL back whenever
it waits for a trigger, and the thread uses that time. The cocotb side takes step k's results
(the model's step, the taps' expected fields) with `get`, in order; a failure in the thread is
raised there.
"""

from __future__ import annotations

import queue
import sys
import threading
from collections.abc import Callable
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
            stream = self.gpf.draw_stream(self.seed)
            mu, chol, sigma = self.state
            steps = len(self.raw_inputs)
            for first in range(0, steps, CHUNK):
                draws = stream.next(min(CHUNK, steps - first))
                if self.corrupt:
                    draws = self.corrupt(draws)
                self.draw_chunks.append(draws)
                for i, e in enumerate(draws):
                    res = self.gpf.step(mu, chol, sigma, self.raw_inputs[first + i], e,
                                        keep_particles=True)
                    mu, chol, sigma = res.mu, res.chol, res.sigma
                    if not self._put(Expected(res, *self.expect(res))):
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
