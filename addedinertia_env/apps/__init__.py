"""Floor 6, applications on the library (beside envs/, vector/, learning/, bench/ and the top-level
hw_adapter/): simulate.py (one simulated run), sweeps.py (local processes or Ray),
energy_budget.py (the energy method's budget on a simulated run) and discovery_dataset.py
(simulated records with known effects, for discovery's detection table).
"""
