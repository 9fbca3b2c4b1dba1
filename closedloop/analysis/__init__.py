"""Analyses built on the compliance: stiffness indices, identification of springs,
stiffness maps, their sweep engine and the Dask executor, design for stiffness."""
