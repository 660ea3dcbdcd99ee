"""Shallow-water Lattice-Boltzmann solver (D2Q9 LABSWE) on OpenCL."""
