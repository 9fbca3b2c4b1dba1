"""Small shared utilities: read-only arrays, LAPACK and BLAS access, the rank rule
and unit-free scaling, finite differences, whole-file output, progress bars, option types."""
