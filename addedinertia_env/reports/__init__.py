"""Generators of docs/*.md: each run as ``python -m addedinertia_env.reports.<name>``."""
