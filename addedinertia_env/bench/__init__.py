"""The controller benchmark: suites of seeded scenarios, an episode runner, a leaderboard.

An episode is an independent task ``(suite, scenario, controller) -> row`` (one JSON
line), so episodes can run in any order, in processes here or on a cluster.
"""

from addedinertia_env.bench.suites import Suite, load_suite

__all__ = ["Suite", "load_suite"]
