"""Learned controllers: training with stable-baselines3, residual learning, ONNX export.

- :mod:`.config`    algorithm configs (``configs/algos/*.yaml``, rl-baselines3-zoo style), validated;
- :mod:`.envs`      vectorised training/evaluation environments and the residual wrapper;
- :mod:`.toy`       a cheap stand-in task with the same observation layout (tests, smoke runs);
- :mod:`.callbacks` evaluation on a fixed seed set, checkpoints with their training cost;
- :mod:`.train`     ``addedinertia train``: one training run, its card and outputs;
- :mod:`.export`    ``addedinertia export``: the deterministic actor with normalisation as ONNX.

Importing this package pulls in torch and stable-baselines3; the rest of the project
does not need it.
"""
