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
    """Calls ``on_expire(reason)`` once when armed and not kicked for ``timeout_s`` (s).

    A daemon thread checks every ``poll_s`` (s; default ``timeout_s / 10``). ``clock`` is
    the time source in s (default :func:`time.perf_counter`); with ``start=False`` no
    thread runs and the owner calls :meth:`poll` itself (tests drive it with a fake clock).
    Raises ValueError for a timeout that is not > 0.
    """

    def __init__(self, timeout_s: float, on_expire: Callable[[str], None], poll_s: float | None = None,
                 clock: Callable[[], float] = time.perf_counter, start: bool = True):
        if not timeout_s > 0:
            raise ValueError(f"watchdog timeout {timeout_s!r} s: expected > 0")
        self.timeout_s = float(timeout_s)
        self.poll_s = poll_s if poll_s is not None else self.timeout_s / 10
        self.on_expire = on_expire
        self.clock = clock
        self.expired = False
        self.expired_at: float | None = None  # clock time it fired
        self._armed = False
        self._last = clock()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="bench-watchdog", daemon=True)
        if start:
            self._thread.start()

    def kick(self) -> None:
        """A valid sample arrived: the quiet time starts again."""
        self._last = self.clock()

    def arm(self, on: bool = True) -> None:
        """Arm (the bench is driven) or pause (the last command was the safe state); arming restarts the quiet time."""
        if on and not self._armed:
            self._last = self.clock()
        self._armed = on

    def close(self) -> None:
        """Stop the thread (waits up to 1 s for it); the watchdog never fires after this."""
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(timeout=1.0)

    def poll(self) -> bool:
        """One check: fire if armed, not yet fired and quiet for longer than ``timeout_s``.

        Returns whether it fired now. An exception from ``on_expire`` is swallowed: the link
        may be gone, and the board's own watchdog then takes over.
        """
        if not self._armed or self.expired:
            return False
        quiet = self.clock() - self._last
        if quiet <= self.timeout_s:
            return False
        self.expired = True
        self.expired_at = self.clock()
        try:
            self.on_expire(f"no sample for {quiet * 1e3:.1f} ms (watchdog {self.timeout_s * 1e3:.0f} ms)")
        except Exception:  # noqa: BLE001 - the link may be gone; the board's watchdog takes over
            pass
        return True

    def _run(self) -> None:
        while not self._stop.wait(self.poll_s):
            self.poll()
