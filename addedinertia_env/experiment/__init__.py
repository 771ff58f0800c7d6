"""The experiments run on a rig: the reverse-symmetric protocol (protocol, runner, reference,
feedforward, two_rate), the free-decay and forced-oscillation kinds, and the energy budget."""
