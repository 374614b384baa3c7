"""Stage: survey."""
