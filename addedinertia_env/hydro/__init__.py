"""Floor 2, hydrodynamics in one place (docs/HYDRODYNAMICS.md): water.py (the water's density
and gravity, once), closed_forms.py (Lamb's spheroid, the Wigley hull, cross-flow damping),
radiation.py (CumminsModel: the radiation memory the simulator integrates), geometry.py
(Wigley, spheroid meshes), mesh_checks.py, bem.py (Capytaine, optional extra [hull]),
study.py (two resolutions, convergence, the cache configs/rigs/PRESET.bem.json),
retardation.py (Cummins K(t)), radiation_ss.py and memory_fit.py (state-space fits of the
memory), estimates.py (Lamb ellipsoid, strip theory), stability.py (sway-yaw course
stability), figures.py. Only bem.py needs Capytaine; everything else reads the cache.
"""
