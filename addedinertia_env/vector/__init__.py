"""The reverse-stroke task on arrays of environments (the batched engine behind a Gymnasium
``VectorEnv`` and a stable-baselines3 ``VecEnv``); see :mod:`.env`."""
