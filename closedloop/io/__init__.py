"""Model files in: URDF + closure files, xacro, MJCF, SDF, bundled and example-robot-data
models, strict YAML, the arithmetic of parametric files."""
