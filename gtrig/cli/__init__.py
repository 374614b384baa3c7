"""The command line: one verb per command, thin wrappers over the library, lazy imports."""
