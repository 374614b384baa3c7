"""Stage: fusion."""
