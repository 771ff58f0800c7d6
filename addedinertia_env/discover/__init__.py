"""Model discovery: what the nominal model gets wrong in measured records, and why.

:func:`discover` fits the nominal gray-box model (physics.md section 8) to all strokes
of all runs by output error, extends it by each candidate effect of the vocabulary of
run-record.md, and names the cause (``docs/DISCOVERY.md``).
"""

from addedinertia_env.discover.diagnose import Diagnosis, Thresholds, discover
from addedinertia_env.discover.prepare import DiscoveryInputError

__all__ = ["Diagnosis", "DiscoveryInputError", "Thresholds", "discover"]
