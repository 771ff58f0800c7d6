"""``sensor_delay``: the current and voltage channel lags the encoders (a sensor term:
the sensor models read :func:`~addedinertia_env.sim.forces.channel_delay`)."""

from __future__ import annotations

from dataclasses import dataclass

from addedinertia_env.sim.effects.registry import EffectSpec, FitRange, Param, register


@dataclass(frozen=True)
class SensorDelay:
    """Parameters of ``sensor_delay``: ``delay`` (s), the lag of the current and voltage channel behind the encoders."""

    delay: float  # s, lag of the current and voltage channel behind the encoders


def channel_delay(e):
    """Lag of the current and voltage channel; s."""
    return e.delay


SPEC = register(EffectSpec(
    name="sensor_delay",
    summary="the current and voltage channel lags the encoders",
    params_type=SensorDelay,
    params=(Param("delay", "s", "lag of the current and voltage channel", realistic=(0.004, 0.012), neutral=0.0,
                  fit=FitRange(0.002, -0.01, 0.05, 1e-3)),),
    size_param="delay",
    min_size=0.002,  # s: four times the zero-order hold's half sample
    channel_delay=channel_delay,
))
