"""Stage: markers."""
