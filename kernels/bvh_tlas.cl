/* The top-level BVH over instances (raytrace.scene.Scene.update). Launch order:
     bvh_reset_info (bvh_build.cl) -> tlas_prep -> bvh_box_morton -> sort -> bvh_hierarchy_boxes
   or, for at most TLAS_ONE_LAUNCH instances, tlas_build_one_group alone (the same steps in one
   work-group, the sort a bitonic one in local memory: the same tree).
   Leaves hold one instance each; tlas_prims (the sorted order) maps a leaf to its instance id. */
#include "bvh_hierarchy.h"
#include "transform.h"

/* Most instances of the one-launch build (a power of two, at most BOUNDS_WG), and the TLAS's
   leaf size (raytrace.scene.TLAS_ONE_LAUNCH, TLAS_LEAF_SIZE mirror them) */
#define TLAS_ONE_LAUNCH 256
#define TLAS_LEAF_SIZE 1

/* Instance records, normal transforms and world boxes from the scene's transform buffer (one
   Transform row per instance: world_from_object, xyz = the 3x3 part, w = translation; written
   by the host or by a device stage) and each mesh's BLAS header (root and object box). The
   BLAS root is the binary root of the header, or with `wide` the mesh's wide root; the
   visibility mask is the host's (inst_mask, Scene.set_instance_mask). The
   inverse is computed here in float with cofactors; the host rejects singular transforms (a
   device writer must not write one). normals[i]: the inverse transpose of the 3x3 part (w = 0),
   the shading normals' transform. The world box is Arvo's transformed box, widened by a few ulps
   of its magnitude so rounding never makes it smaller than the moved geometry.
   Instance i's: *c_out is its box's centre, or +inf for an instance of an empty mesh. */
inline void tlas_prep_instance(int i, __global const Transform* restrict xforms,
                               __global const int* restrict inst_mesh,
                               __global const int* restrict mesh_prim_base,
                               __global const BvhInfo* restrict blas_infos,
                               __global const int* restrict mesh_wide_root, int wide,
                               __global const uint* restrict inst_mask,
                               __global Instance* restrict instances,
                               __global Transform* restrict normals,
                               __global float4* restrict boxes, float3* c_out) {
    const Transform x = xforms[i];
    const float4 r0 = x.r0, r1 = x.r1, r2 = x.r2;
    int mesh = inst_mesh[i];
    BvhInfo bi = blas_infos[mesh];
    /* inverse of the 3x3 part: adjugate / determinant */
    float3 c0 = cross(r1.xyz, r2.xyz), c1 = cross(r2.xyz, r0.xyz), c2 = cross(r0.xyz, r1.xyz);
    float inv_det = 1.0f / dot(r0.xyz, c0);
    float3 t = (float3)(r0.w, r1.w, r2.w);
    /* rows of the inverse are the columns of the adjugate */
    float3 q0 = (float3)(c0.x, c1.x, c2.x) * inv_det;
    float3 q1 = (float3)(c0.y, c1.y, c2.y) * inv_det;
    float3 q2 = (float3)(c0.z, c1.z, c2.z) * inv_det;
    Instance ins;
    ins.object_from_world[0] = (float4)(q0, -dot(q0, t));
    ins.object_from_world[1] = (float4)(q1, -dot(q1, t));
    ins.object_from_world[2] = (float4)(q2, -dot(q2, t));
    ins.blas_root = bi.root >= 0 && wide ? mesh_wide_root[mesh] : bi.root;
    ins.mesh = mesh;
    ins.prim_base = mesh_prim_base[mesh];
    ins.mask = inst_mask[i];
    instances[i] = ins;
    /* inverse transpose: its rows are the columns of the inverse, i.e. cofactors / det */
    Transform nx;
    nx.r0 = (float4)(c0 * inv_det, 0.0f);
    nx.r1 = (float4)(c1 * inv_det, 0.0f);
    nx.r2 = (float4)(c2 * inv_det, 0.0f);
    normals[i] = nx;
    float3 lo = (float3)(INFINITY), hi = (float3)(-INFINITY);
    if (bi.root >= 0) {
        float3 c = 0.5f * (bi.lo.xyz + bi.hi.xyz), e = 0.5f * (bi.hi.xyz - bi.lo.xyz);
        float3 wc = (float3)(dot(r0.xyz, c), dot(r1.xyz, c), dot(r2.xyz, c)) + t;
        float3 we = (float3)(dot(fabs(r0.xyz), e), dot(fabs(r1.xyz), e),
                             dot(fabs(r2.xyz), e));
        float3 pad = (fabs(wc) + we) * 1e-6f + 1e-30f;
        lo = wc - we - pad;
        hi = wc + we + pad;
    }
    boxes[2 * i] = (float4)(lo, 0.0f);
    boxes[2 * i + 1] = (float4)(hi, 0.0f);
    const float3 c = 0.5f * (lo + hi);
    *c_out = bi.root >= 0 && isfinite(c.x) && isfinite(c.y) && isfinite(c.z) ? c
                                                                             : (float3)(INFINITY);
}

__kernel __attribute__((reqd_work_group_size(BOUNDS_WG, 1, 1)))
void tlas_prep(int n_inst, __global const Transform* restrict xforms,
               __global const int* restrict inst_mesh, __global const int* restrict mesh_prim_base,
               __global const BvhInfo* restrict blas_infos,
               __global const int* restrict mesh_wide_root, int wide,
               __global const uint* restrict inst_mask, __global Instance* restrict instances,
               __global Transform* restrict normals,
               __global float4* restrict boxes, __global BvhInfo* tlas_info) {
    __local float lmin[3 * BOUNDS_WG], lmax[3 * BOUNDS_WG];
    int i = get_global_id(0);
    float3 c = (float3)(INFINITY);
    if (i < n_inst)
        tlas_prep_instance(i, xforms, inst_mesh, mesh_prim_base, blas_infos, mesh_wide_root, wide,
                           inst_mask, instances, normals, boxes, &c);
    reduce_centroid_bounds(c, isfinite(c.x) ? c : (float3)(-INFINITY), lmin, lmax, tlas_info);
}

/* Morton keys of box centroids; vals = box index. */
__kernel void bvh_box_morton(int n, __global const float4* restrict boxes,
                             __global const BvhInfo* restrict info, int key_bits,
                             __global uint* restrict keys, __global uint* restrict vals) {
    int i = get_global_id(0);
    if (i >= n) return;
    keys[i] = bvh_box_key(boxes, i, info, key_bits);
    vals[i] = i;
}

/* Hierarchy over boxes in sorted order (order[k] = box of sorted position k). */
__kernel void bvh_hierarchy_boxes(int n, int leaf_size, __global const uint* restrict keys,
                                  __global const uint* restrict order,
                                  __global const float4* restrict boxes, __global BvhNode* nodes,
                                  __global int* flags, __global BvhInfo* info) {
    int i = get_global_id(0);
    if (i < n) bvh_hierarchy_box_item(i, n, leaf_size, keys, order, boxes, nodes, flags, info);
}

/* The whole TLAS of n_inst <= TLAS_ONE_LAUNCH instances in one work-group: the header reset,
   tlas_prep, bvh_box_morton, a stable sort of the keys (bitonic on (key, index) in local
   memory: the order of the radix sort) and bvh_hierarchy_boxes, the same tree as the five
   launches (a TLAS of a few instances is launch-bound: 4 launches less a frame). */
__kernel __attribute__((reqd_work_group_size(BOUNDS_WG, 1, 1)))
void tlas_build_one_group(int n_inst, __global const Transform* restrict xforms,
                          __global const int* restrict inst_mesh,
                          __global const int* restrict mesh_prim_base,
                          __global const BvhInfo* restrict blas_infos,
                          __global const int* restrict mesh_wide_root, int wide,
                          __global const uint* restrict inst_mask,
                          __global Instance* restrict instances,
                          __global Transform* restrict normals, __global float4* boxes,
                          __global uint* keys, __global uint* order, __global BvhNode* nodes,
                          __global int* flags, __global BvhInfo* info) {
    __local float lmin[3 * BOUNDS_WG], lmax[3 * BOUNDS_WG];
    __local uint lkey[TLAS_ONE_LAUNCH], lval[TLAS_ONE_LAUNCH];
    const int i = get_local_id(0), n = n_inst;
    if (i == 0) bvh_info_reset(info, n); /* bvh_reset_info */
    barrier(CLK_GLOBAL_MEM_FENCE);
    float3 c = (float3)(INFINITY);
    if (i < n)
        tlas_prep_instance(i, xforms, inst_mesh, mesh_prim_base, blas_infos, mesh_wide_root, wide,
                           inst_mask, instances, normals, boxes, &c);
    reduce_centroid_bounds(c, isfinite(c.x) ? c : (float3)(-INFINITY), lmin, lmax, info);
    barrier(CLK_GLOBAL_MEM_FENCE);
    if (i < TLAS_ONE_LAUNCH) { /* bvh_box_morton; past n: keys after every real one */
        lkey[i] = i < n ? bvh_box_key(boxes, i, info, 32) : 0xffffffffu;
        lval[i] = (uint)i;
    }
    for (int size = 2; size <= TLAS_ONE_LAUNCH; size <<= 1) {
        for (int stride = size >> 1; stride > 0; stride >>= 1) {
            barrier(CLK_LOCAL_MEM_FENCE);
            const int j = i ^ stride;
            if (i < TLAS_ONE_LAUNCH && j > i) {
                const bool up = (i & size) == 0;
                const uint ki = lkey[i], kj = lkey[j], vi = lval[i], vj = lval[j];
                const bool greater = ki > kj || (ki == kj && vi > vj);
                if (greater == up) {
                    lkey[i] = kj;
                    lkey[j] = ki;
                    lval[i] = vj;
                    lval[j] = vi;
                }
            }
        }
    }
    barrier(CLK_LOCAL_MEM_FENCE);
    if (i < n) {
        keys[i] = lkey[i];
        order[i] = lval[i];
    }
    barrier(CLK_GLOBAL_MEM_FENCE);
    if (i < n) /* bvh_hierarchy_boxes */
        bvh_hierarchy_box_item(i, n, TLAS_LEAF_SIZE, keys, order, boxes, nodes, flags, info);
}
