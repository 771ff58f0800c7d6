"""Floor 2, the loops between a controller and the drive, on the rig contract only:
control_loop.py (ControlLoop, LoopRig: in-loop reading delay, set-point rate, current quantum)
and board_loop.py (the two-rate board's inner loop, written once: the emulator's board, the
simulator's TwoRateSimRig and the C reference in firmware/ share it).
"""
