/* The top-level BVH over instances (raytrace.scene.Scene.update). Launch order:
     bvh_reset_info (bvh_build.cl) -> tlas_prep -> bvh_box_morton -> sort -> bvh_hierarchy_boxes
   Leaves hold one instance each; tlas_prims (the sorted order) maps a leaf to its instance id. */
#include "bvh_hierarchy.h"
#include "transform.h"

/* Instance records, normal transforms and world boxes from the scene's transform buffer (one
   Transform row per instance: world_from_object, xyz = the 3x3 part, w = translation; written
   by the host or by a device stage) and each mesh's BLAS header (root and object box). The
   BLAS root is the binary root of the header, or with `wide` the mesh's wide root; the
   visibility mask is the host's (inst_mask, Scene.set_instance_mask). The
   inverse is computed here in float with cofactors; the host rejects singular transforms (a
   device writer must not write one). normals[i]: the inverse transpose of the 3x3 part (w = 0),
   the shading normals' transform. The world box is Arvo's transformed box, widened by a few ulps
   of its magnitude so rounding never makes it smaller than the moved geometry. */
__kernel __attribute__((reqd_work_group_size(BOUNDS_WG, 1, 1)))
void tlas_prep(int n_inst, __global const Transform* restrict xforms,
               __global const int* restrict inst_mesh, __global const int* restrict mesh_prim_base,
               __global const BvhInfo* restrict blas_infos,
               __global const int* restrict mesh_wide_root, int wide,
               __global const uint* restrict inst_mask, __global Instance* restrict instances, __global Transform* restrict normals,
               __global float4* restrict boxes, __global BvhInfo* tlas_info) {
    __local float lmin[3 * BOUNDS_WG], lmax[3 * BOUNDS_WG];
    int i = get_global_id(0);
    float3 cmin = (float3)(INFINITY), cmax = (float3)(-INFINITY);
    if (i < n_inst) {
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
            cmin = cmax = 0.5f * (lo + hi);
        }
        boxes[2 * i] = (float4)(lo, 0.0f);
        boxes[2 * i + 1] = (float4)(hi, 0.0f);
    }
    bool ok = isfinite(cmin.x) && isfinite(cmin.y) && isfinite(cmin.z);
    reduce_centroid_bounds(ok ? cmin : (float3)(INFINITY), ok ? cmax : (float3)(-INFINITY),
                           lmin, lmax, tlas_info);
}

/* Morton keys of box centroids; vals = box index. */
__kernel void bvh_box_morton(int n, __global const float4* restrict boxes,
                             __global const BvhInfo* restrict info, int key_bits,
                             __global uint* restrict keys, __global uint* restrict vals) {
    int i = get_global_id(0);
    if (i >= n) return;
    float3 lo, ext;
    morton_frame(info, &lo, &ext);
    uint4 masks = morton_masks(ext, key_bits);
    float3 c = 0.5f * (boxes[2 * i].xyz + boxes[2 * i + 1].xyz);
    keys[i] = morton_isotropic(c, lo, ext, masks);
    vals[i] = i;
}

/* Hierarchy over boxes in sorted order (order[k] = box of sorted position k). */
__kernel void bvh_hierarchy_boxes(int n, int leaf_size, __global const uint* restrict keys,
                                  __global const uint* restrict order,
                                  __global const float4* restrict boxes, __global BvhNode* nodes,
                                  __global int* flags, __global BvhInfo* info) {
    int i = get_global_id(0);
    if (i >= n) return;
    if (n <= leaf_size) {
        if (i != 0) return;
        float3 lo = (float3)(INFINITY), hi = (float3)(-INFINITY);
        for (int k = 0; k < n; ++k) {
            lo = fmin(lo, boxes[2 * order[k]].xyz);
            hi = fmax(hi, boxes[2 * order[k] + 1].xyz);
        }
        bvh_small_root(n, 0, 0, nodes, info, lo, hi);
        return;
    }
    uint b = order[i];
    bvh_walk(i, n, leaf_size, 0, 0, keys, nodes, flags, info, boxes[2 * b].xyz,
             boxes[2 * b + 1].xyz);
}
