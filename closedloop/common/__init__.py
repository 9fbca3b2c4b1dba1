"""Small shared utilities: read-only arrays, LAPACK and BLAS access, the rank rule
and unit-free scaling, finite differences, whole-file output, input files read within
limits, progress bars, option types."""
