"""Floor 0, foundation: atomic file writes (atomic), the machine line (machine), YAML
configuration with one refusal, ConfigError, and the configs/ folder (config_io), strict JSON
(jsonable). Imports nothing of the project but the package root.
"""
