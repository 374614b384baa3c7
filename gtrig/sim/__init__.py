"""The simulator: a replica of the RAWSEEDS GT room that writes recordings in the real on-disk formats,
plus the truth. Physical sources of every simulated effect are written down in docs/simulator.md."""
