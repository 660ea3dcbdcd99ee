/* BVH device structs shared by the builder (bvh_build.cl, bvh_tlas.cl) and traversal
   (traverse.h). Each struct is mirrored by one NumPy dtype in raytrace/bvh.py and its layout is
   proved on the device by tests/raytrace/test_bvh_layout.py. */
#ifndef LBWATER_BVH_H
#define LBWATER_BVH_H

/* A binary node that holds both children's boxes (Aila & Laine 2009), so one node fetch tests
   both children. 64 bytes: four float4 loads. The w words carry int bits (as_int):
     lo_l.w = left ref,  hi_l.w = left count,  lo_r.w = right ref,  hi_r.w = right count.
   count > 0 : a leaf of `count` primitives starting at primitive `ref` (absolute index);
   count == 0: an inner node, `ref` is its absolute node index;
   count < 0 : no child (only in a root of fewer than two leaves); never entered. */
typedef struct {
    float4 lo_l;
    float4 hi_l;
    float4 lo_r;
    float4 hi_r;
} BvhNode;

#define BVH_CHILD_EMPTY (-1)

/* A triangle in BVH leaf order, its vertices gathered so a leaf test reads 48 contiguous bytes:
   p0.w = as_float(prim), the triangle's index in the mesh's own (input) order. 48 bytes. */
typedef struct {
    float4 p0;
    float4 p1;
    float4 p2;
} BvhTri;

/* Per-BVH header written on the device by the build (80 bytes).
   root   : absolute index of the root node, -1 while the BVH holds no primitive;
   n_prims: primitives in the BVH;
   n_bad  : primitives with a non-finite coordinate seen by the last build or refit;
   depth_guard: set to 1 if a bottom-up walk ever ran longer than BVH_MAX_WALK (never expected);
   lo, hi : the root box (xyz; w unused);
   cmin, cmax: centroid bounds as order-preserving ints (build scratch, see float_to_ordered). */
typedef struct {
    int root;
    int n_prims;
    int n_bad;
    int depth_guard;
    float4 lo;
    float4 hi;
    int4 cmin;
    int4 cmax;
} BvhInfo;

/* One instance of a mesh, filled on the device by the TLAS build from the host's transform
   (64 bytes). object_from_world: rows of the inverse affine transform (a ray is moved into the
   mesh's space with it; t is unchanged by an affine map). blas_root: root node of the mesh's BVH in
   the scene's node array (-1: empty mesh). mesh: mesh id. prim_base: the mesh's first triangle in
   the scene-wide numbering (sum of the triangle counts of the meshes added before it). */
typedef struct {
    float4 object_from_world[3];
    int blas_root;
    int mesh;
    int prim_base;
    int pad;
} Instance;

/* A float and an int that order alike: a < b as floats iff ordered(a) < ordered(b) as ints. */
inline int float_to_ordered(float f) {
    int i = as_int(f);
    return i >= 0 ? i : i ^ 0x7fffffff;
}
inline float ordered_to_float(int i) {
    return as_float(i >= 0 ? i : i ^ 0x7fffffff);
}

#endif
