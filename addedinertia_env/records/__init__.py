"""Floor 2, run records: the format in memory (run_record.py: RunRecord, RecordError), the
strict reader and writer (record.py, CSV + JSON), the model-free plausibility check
(plausibility.py), the DAQ quirks a reader meets (daq.py), plots of a record (plots.py), and
their compiled passes (record_kernels.py, scan_kernels.py) and order statistics (series_stats.py).
"""
