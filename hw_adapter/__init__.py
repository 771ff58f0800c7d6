"""The real bench (and its emulator) behind the rig protocol of ``addedinertia_env/rig/interface.py``.

Modules, from the wire up (docs/PROTOCOL.md, docs/BENCH.md):

* ``framing``: frames (sync, version, type, seq, length, time, payload, CRC-32) and the
  streaming parser;
* ``messages``: payload layouts of protocol version 1 (HELLO, CAPS, RESET, ARM, DISARM,
  COMMAND, SAMPLE, FAULT, HEARTBEAT, QUERY) and version 2, the two-rate bench (SEGMENT,
  SAMPLE_BATCH; the board's inner loop is ``addedinertia_env/loop/board_loop.py``);
* ``link``: the host end over pyserial (``/dev/ttyUSB0``, ``socket://``, ``loop://``);
* ``safety``: the envelope between any controller and the link; ``watchdog``: the host
  watchdog thread;
* ``bench_rig``: :class:`~hw_adapter.bench_rig.BenchRig`, the Rig protocol on a bench;
* ``lab``: the lab file (what the board cannot report); ``recorder``: the run record
  written as it goes; ``deploy``: one experiment, ``addedinertia deploy``;
* ``board``, ``emulator``, ``faults``: the simulated bench behind the protocol,
  ``addedinertia bench-server``; ``loopback``: starting it in tests; ``measure``: the
  figures of docs/BENCH.md.
"""
