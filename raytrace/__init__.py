"""GPU BVH (LBVH build, refit, two-level instances), ray queries and the wavefront renderer."""
