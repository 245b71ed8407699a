"""The ground floor: units, errors, TOML and file I/O, limits, layout geometry, shared physics.

Imports nothing of gyroarray above it."""
