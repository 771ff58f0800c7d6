""":class:`RecordError`: a run record that cannot be used (its form, its content, its physics).

Apart from :mod:`addedinertia_env.records.run_record` so that the plausibility check, which the run
record's views call, can raise it without importing the record; both
:mod:`addedinertia_env.records.run_record` and :mod:`addedinertia_env.records.record` re-export it.
"""

from __future__ import annotations


class RecordError(ValueError):
    """A run record that cannot be used; the message names file, place, value, expectation."""
