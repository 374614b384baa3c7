"""Stage: vision."""
