"""Floor 4, the experiment: the reverse-symmetric protocol (protocol, runner, reference and its
compiled stroke_kernels, filters, sample_log, feedforward, two_rate), the free-decay and
forced-oscillation kinds, the oracle controller (tests only); the task (task.py: observation,
action, reward terms, ControllerContext), the episode metrics (metrics.py) and the seeded
scenarios (scenarios.py).
"""
