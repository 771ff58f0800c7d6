"""Smoothing of dry friction, shared by the hull bearing effect and the motor's rotor friction."""

# Smoothing rate scale for dry friction, rad/s. Below this speed the friction torque is
# proportional to speed; 1e-3 rad/s is well under one hull-encoder count per 50 ms.
DRY_FRICTION_RATE_SCALE = 1e-3
# The motor rotor's dry friction is smoothed over ten times that (forces.flywheel_friction_torque).
# The simulator's law only: the energy method chooses its own smoothing from what a record can
# resolve (identify/rotor_friction.py).
ROTOR_FRICTION_RATE_SCALE = 10 * DRY_FRICTION_RATE_SCALE
