"""Stage: laser."""
