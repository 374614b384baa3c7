from fusion_synth import run  # noqa: F401  (the session fixture)
