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

/* Per-BVH header written on the device by the build (96 bytes).
   root   : absolute index of the root node, -1 while the BVH holds no primitive;
   n_prims: primitives in the BVH;
   n_bad  : primitives with a non-finite coordinate seen by the last build or refit;
   depth_guard: set to 1 if a bottom-up walk ever ran longer than BVH_MAX_WALK (never expected);
   lo, hi : the root box (xyz; w unused);
   cmin, cmax: centroid bounds as order-preserving ints (build scratch, see float_to_ordered);
   n_bad_pending: the count of the launch under way; the work-item that completes the root moves
   it to n_bad and zeroes it, so a refit needs no header reset launch. */
typedef struct {
    int root;
    int n_prims;
    int n_bad;
    int depth_guard;
    float4 lo;
    float4 hi;
    int4 cmin;
    int4 cmax;
    int n_bad_pending;
    int pad[3];
} BvhInfo;

/* The wide layout for CPU devices (TRACE_WIDE, raytrace/bvh_wide.py): the binary tree collapsed
   into 8-wide nodes whose child boxes are stored as planes across the children (SoA), so one
   ray tests all eight with a few float8 operations, and leaves stored as blocks of 4 triangles in
   SoA, tested with float4 operations. A CPU runs one ray per work-item as scalar code: the width
   has to come from inside the ray's own work (Embree's single-ray layout). */
#define WIDE_WIDTH 8
#define WIDE_BLOCK 4
/* Levels of a wide tree (it is never deeper than its binary tree, whose depth the builder bounds
   by 62 (raytrace.bvh.expected_depth_bound: 32 key bits + 30 index bits). */
#define WIDE_MAX_LEVELS 64

/* 256 bytes. plane[a] holds axis a%3 of the children's lower (a < 3) or upper (a >= 3) corner.
   cnt > 0: a leaf of cnt triangles in the (cnt + 3) / 4 blocks from block `ref` (absolute);
   cnt == 0: an inner child, `ref` its absolute wide node index; cnt < 0: no child (its box is
   empty: lower +inf, upper -inf, so no ray enters it). */
typedef struct {
    float8 plane[6];
    int8 ref;
    int8 cnt;
} WideNode;

/* 160 bytes: 4 triangles of one leaf, v[vertex][axis] across the 4 lanes; lanes past the leaf's
   end repeat the block's first triangle (the same hit, never a false one). prim: input-order
   index. */
typedef struct {
    float4 v[3][3];
    int4 prim;
} TriBlock;

/* Per-BVH header of the wide tree's build (272 bytes): wide nodes per level (level 0 is the
   root; a level's nodes follow the previous level's, so node i of level L is at
   sum(level_count[0..L-1]) + i), their sum (written by the refit), blocks used, and
   truncated = 1 if a node of the last level had an inner child (never expected, see
   WIDE_MAX_LEVELS). */
typedef struct {
    int level_count[WIDE_MAX_LEVELS];
    int n_nodes;
    int n_blocks;
    int truncated;
    int pad;
} WideInfo;

/* One instance of a mesh, filled on the device by the TLAS build from the host's transform
   (64 bytes). object_from_world: rows of the inverse affine transform (a ray is moved into the
   mesh's space with it; t is unchanged by an affine map). blas_root: root node of the mesh's BVH in
   the scene's node array, binary or wide by the scene's layout (-1: empty mesh). mesh: mesh id.
   prim_base: the mesh's first triangle in the scene-wide numbering (sum of the triangle counts of
   the meshes added before it). mask: visibility bits; a ray traced with a mask sees the instance
   only when the two share a bit (all bits by default: raytrace.scene.Scene.set_instance_mask). */
typedef struct {
    float4 object_from_world[3];
    int blas_root;
    int mesh;
    int prim_base;
    uint mask;
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
