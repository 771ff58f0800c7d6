"""The host watchdog: a thread that makes the bench safe if the control loop goes quiet.

The control loop :meth:`~Watchdog.kick`\\ s it on every valid sample. While it is
*armed* (the bench is driven: a current or voltage command, or the brake released) and
no kick comes for ``timeout_s``, it calls ``on_expire`` once, from its own thread: that
sends the safe state (zero current, brake, DISARM) even when the loop is stuck in a
controller, a blocked read or a pause. It is paused whenever the last command already
was the safe state, because then there is nothing to stop.

Worst-case time from the last sample to the safe command: ``timeout_s + poll_s``, with
``poll_s = timeout_s / 10`` by default (22 ms for the 20 ms watchdog).
"""

from __future__ import annotations

import threading
import time
from typing import Callable


class Watchdog:
    def __init__(self, timeout_s: float, on_expire: Callable[[str], None], poll_s: float | None = None):
        if not timeout_s > 0:
            raise ValueError(f"watchdog timeout {timeout_s!r} s: expected > 0")
        self.timeout_s = float(timeout_s)
        self.poll_s = poll_s if poll_s is not None else self.timeout_s / 10
        self.on_expire = on_expire
        self.expired = False
        self.expired_at: float | None = None  # perf_counter time it fired
        self._armed = False
        self._last = time.perf_counter()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="bench-watchdog", daemon=True)
        self._thread.start()

    def kick(self) -> None:
        self._last = time.perf_counter()

    def arm(self, on: bool = True) -> None:
        if on and not self._armed:
            self._last = time.perf_counter()
        self._armed = on

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=1.0)

    def _run(self) -> None:
        while not self._stop.wait(self.poll_s):
            if self._armed and not self.expired:
                quiet = time.perf_counter() - self._last
                if quiet > self.timeout_s:
                    self.expired = True
                    self.expired_at = time.perf_counter()
                    try:
                        self.on_expire(f"no sample for {quiet * 1e3:.1f} ms (watchdog {self.timeout_s * 1e3:.0f} ms)")
                    except Exception:  # noqa: BLE001 - the link may be gone; the board's watchdog takes over
                        pass
