"""Model files in: URDF + closure files, MJCF, SDF, bundled and example-robot-data
models, strict YAML."""
