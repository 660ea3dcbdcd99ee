"""Shallow-water Lattice-Boltzmann solver (D2Q9 LABSWE, Zhou 2004) on OpenCL, float32.

    import lbm
    sim = lbm.ShallowWater(256, 256, 0.01, boundary="slip")
    sim.set_state(h, u, v, bed)      # numpy (ny, nx), SI units
    sim.step(10)
    sim.fields(), sim.dt, sim.time, sim.stats()

See docs/lbm.md.
"""

from lbm.lattice import Lattice, Options, choose_lattice
from lbm.mesh import grid_triangles
from lbm.solver import Boundary, ShallowWater, Storage
from lbm.spec import from_water_spec

__all__ = ["Boundary", "Lattice", "Options", "ShallowWater", "Storage", "choose_lattice",
           "from_water_spec", "grid_triangles"]
