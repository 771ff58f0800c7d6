"""Floor 3, the simulator: the rig's model, laws and engines behind the rig contract.
params.py (frozen dataclasses with units), presets.py (YAML presets, strict validation),
hull_presets.py (a preset's hull geometry and its BEM cache), effects/ (hidden truth effects,
one file each, and their registry), forces.py (one source of every generalised force),
friction.py, motor.py (exact current update), sensors.py and noise.py (one sensor model on
arrays), integrator.py, simulated.py (what every simulated rig shares), mujoco_rig.py
(MujocoRig), batched*.py (BatchedRig and its single view), kernels.py (the batched rig's
compiled loops).
"""
