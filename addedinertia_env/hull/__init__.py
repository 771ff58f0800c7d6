"""Hull hydrodynamics from geometry (issue 15; docs/HYDRODYNAMICS.md).

* :mod:`.geometry`: the presets' analytic hulls (Wigley, prolate spheroid) as panel meshes.
* :mod:`.mesh_checks`: closed, outward, no internal lid, immersed.
* :mod:`.bem`: the radiation solve with Capytaine (optional extra ``[hull]``).
* :mod:`.study`: two resolutions, convergence, and the cache beside the preset.
* :mod:`.retardation`: Cummins' kernel from B66 and Ogilvie's check.
* :mod:`.estimates`: Lamb's ellipsoid and strip theory, for comparison.
* :mod:`.stability`: the ship's sway-yaw course stability from the added masses.

Only :mod:`.bem` (and what calls it) needs Capytaine; everything else reads the cache.
"""
