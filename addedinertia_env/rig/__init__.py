"""The rig and its physics: parameters and presets (params, presets, known), the engines
(mujoco_rig, batched), forces and effects, sensors, and the loops between a controller and
the drive (control_loop, board_loop). Layer 1, physics (docs/ARCHITECTURE.md)."""
