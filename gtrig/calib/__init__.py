"""Stage: calib."""
