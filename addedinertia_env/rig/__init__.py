"""Floor 1, the rig contract: what the experiment, the task, the board loop and the bench need of
a rig, and nothing of how it is simulated. interface.py: the Rig protocol; known.py: KnownRig,
what the experimenter knows (the run record's rig block, typed); signals.py: MotorCommand (and
its MODES) and Reading, the drive's command and the sample the data acquisition reports.
"""
