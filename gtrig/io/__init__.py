"""File I/O: the recording layout, trajectories, scans, CSV tables. Depends on the core, never on the CLI."""
