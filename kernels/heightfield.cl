/* The height field's per-frame pass (raytrace.scene.Scene.update), in place of a BVH refit:
     heightfield_bounds   one launch, one work-item per HF_BLOCK x HF_BLOCK block of cells
   Reads each vertex of its block once ((HF_BLOCK + 1)^2 reads: block edges are shared) and
   writes 16 bytes per block (its y range and a bound on its slopes) and the grid's box and
   slope bound into the HeightField record, and the box into the mesh's BvhInfo header, which
   the TLAS build reads as it reads a BLAS's root box. */
#include "bvh.h"
#include "heightfield.h"

/* A bound on the slopes of the triangles whose x edges rise by at most rise_x and z edges by
   rise_z: a triangle's slope over x is one x edge's step over dx (over z: a z edge's), up to
   the off-grid tolerance, which HF_SLOPE_MARGIN covers. */
inline float hf_slope_bound(float rise_x, float rise_z, float dx, float dz)
{
    const float sx = rise_x / fabs(dx), sz = rise_z / fabs(dz);
    return HF_SLOPE_MARGIN * sqrt(sx * sx + sz * sz);
}

inline void hf_group_min_max(__local int* l, int lid, int* v, int is_max)
{
    l[lid] = *v;
    barrier(CLK_LOCAL_MEM_FENCE);
    for (int s = HF_WG / 2; s > 0; s >>= 1) {
        if (lid < s) l[lid] = is_max ? max(l[lid], l[lid + s]) : min(l[lid], l[lid + s]);
        barrier(CLK_LOCAL_MEM_FENCE);
    }
    *v = l[0];
    barrier(CLK_LOCAL_MEM_FENCE);
}

/* blocks[b] = (min y, max y, slope bound, 0) of block b = bj * nbx + bi (cells [bi B, bi B + B)
   x [bj B, bj B + B), vertices up to and including the far edge; the bound as HeightField.slope
   over the block's own edges); the work-groups' boxes, steps and bad-vertex counts go through
   atomics on order-preserving ints, and the last group to finish (a ticket after a global
   fence) writes the grid's box, slope bound and count and resets the scratch. */
__kernel __attribute__((reqd_work_group_size(HF_WG, 1, 1)))
void heightfield_bounds(__global const float4* restrict verts, __global float4* restrict blocks,
                        __global HeightField* hf, __global BvhInfo* restrict blas_infos)
{
    __local int scratch[HF_WG];
    const int lid = get_local_id(0), b = get_global_id(0);
    const int nx = hf->nx, ny = hf->ny, nbx = hf->nbx, nby = hf->nby;
    const float4 v00 = verts[0], vx = verts[nx - 1], vz = verts[(ny - 1) * nx];
    const float dx = (vx.x - v00.x) / (float)(nx - 1), dz = (vz.z - v00.z) / (float)(ny - 1);
    const float tol_x = HF_GRID_TOL * fabs(dx), tol_z = HF_GRID_TOL * fabs(dz);
    int lo[3] = {INT_MAX, INT_MAX, INT_MAX}, hi[3] = {INT_MIN, INT_MIN, INT_MIN};
    int bad = 0;
    /* the largest height step along an x edge and along a z edge (a non-finite vertex:
       INFINITY), the previous row's heights in local memory */
    float rise_x = 0.0f, rise_z = 0.0f;
    __local float rows[HF_WG * (HF_BLOCK + 1)];
    __local float* above = rows + lid * (HF_BLOCK + 1);
    if (b < nbx * nby) {
        const int bi = b % nbx, bj = b / nbx;
        const int i0 = bi * HF_BLOCK, i1 = min(i0 + HF_BLOCK, nx - 1);
        const int j0 = bj * HF_BLOCK, j1 = min(j0 + HF_BLOCK, ny - 1);
        float ymin = INFINITY, ymax = -INFINITY;
        float3 blo = (float3)(INFINITY), bhi = (float3)(-INFINITY);
        for (int j = j0; j <= j1; ++j) {
            const float zj = v00.z + (float)j * dz;
            float left = 0.0f;
            for (int i = i0; i <= i1; ++i) {
                const float4 v = verts[j * nx + i];
                const bool finite = isfinite(v.x) && isfinite(v.y) && isfinite(v.z);
                const bool on_grid = fabs(v.x - (v00.x + (float)i * dx)) <= tol_x
                                     && fabs(v.z - zj) <= tol_z;
                /* count each vertex once: in the block whose near corner it is or, on the
                   grid's far edges, the last block */
                const bool own = (i < i1 || i == nx - 1) && (j < j1 || j == ny - 1);
                if (own && !(finite && on_grid)) bad++;
                if (i > i0) rise_x = fmax(rise_x, fabs(v.y - left));
                if (j > j0) rise_z = fmax(rise_z, fabs(v.y - above[i - i0]));
                left = above[i - i0] = v.y;
                if (!finite) {
                    rise_x = INFINITY;
                    continue;
                }
                ymin = fmin(ymin, v.y);
                ymax = fmax(ymax, v.y);
                blo = fmin(blo, v.xyz);
                bhi = fmax(bhi, v.xyz);
            }
        }
        blocks[b] = (float4)(ymin, ymax, hf_slope_bound(rise_x, rise_z, dx, dz), 0.0f);
        lo[0] = float_to_ordered(blo.x);
        lo[1] = float_to_ordered(blo.y);
        lo[2] = float_to_ordered(blo.z);
        hi[0] = float_to_ordered(bhi.x);
        hi[1] = float_to_ordered(bhi.y);
        hi[2] = float_to_ordered(bhi.z);
    }
    for (int a = 0; a < 3; ++a) {
        hf_group_min_max(scratch, lid, &lo[a], 0);
        hf_group_min_max(scratch, lid, &hi[a], 1);
    }
    int steep_x = float_to_ordered(rise_x), steep_z = float_to_ordered(rise_z);
    hf_group_min_max(scratch, lid, &steep_x, 1);
    hf_group_min_max(scratch, lid, &steep_z, 1);
    scratch[lid] = bad;
    barrier(CLK_LOCAL_MEM_FENCE);
    for (int s = HF_WG / 2; s > 0; s >>= 1) {
        if (lid < s) scratch[lid] += scratch[lid + s];
        barrier(CLK_LOCAL_MEM_FENCE);
    }
    if (lid != 0) return;
    __global int* acc_lo = (__global int*)&hf->acc_lo;
    __global int* acc_hi = (__global int*)&hf->acc_hi;
    for (int a = 0; a < 3; ++a) {
        atomic_min(acc_lo + a, lo[a]);
        atomic_max(acc_hi + a, hi[a]);
    }
    if (scratch[0]) atomic_add(&hf->acc_bad, scratch[0]);
    atomic_max(&hf->acc_rise_x, steep_x);
    atomic_max(&hf->acc_rise_z, steep_z);
    mem_fence(CLK_GLOBAL_MEM_FENCE);
    if (atomic_inc(&hf->ticket) != (int)get_num_groups(0) - 1) return;
    /* the last group: every other group's atomics are in */
    float4 box_lo, box_hi;
    box_lo.x = ordered_to_float(atomic_xchg(acc_lo + 0, INT_MAX));
    box_lo.y = ordered_to_float(atomic_xchg(acc_lo + 1, INT_MAX));
    box_lo.z = ordered_to_float(atomic_xchg(acc_lo + 2, INT_MAX));
    box_hi.x = ordered_to_float(atomic_xchg(acc_hi + 0, INT_MIN));
    box_hi.y = ordered_to_float(atomic_xchg(acc_hi + 1, INT_MIN));
    box_hi.z = ordered_to_float(atomic_xchg(acc_hi + 2, INT_MIN));
    box_lo.w = box_hi.w = 0.0f;
    const int n_bad = atomic_xchg(&hf->acc_bad, 0);
    hf->slope = hf_slope_bound(ordered_to_float(atomic_xchg(&hf->acc_rise_x, INT_MIN)),
                               ordered_to_float(atomic_xchg(&hf->acc_rise_z, INT_MIN)), dx, dz);
    hf->lo = box_lo;
    hf->hi = box_hi;
    hf->x0 = v00.x;
    hf->z0 = v00.z;
    hf->cells_per_x = 1.0f / dx;
    hf->cells_per_z = 1.0f / dz;
    hf->n_bad = n_bad;
    atomic_xchg(&hf->ticket, 0);
    __global BvhInfo* info = blas_infos + hf->mesh;
    info->root = 0; /* a live instance: the walk, not a node, is what the traversal enters */
    info->n_prims = 2 * (nx - 1) * (ny - 1);
    info->n_bad = n_bad;
    info->lo = box_lo;
    info->hi = box_hi;
}

/* Tests, object space: out[i] = hf_climbs(dirs[i]) | hf_sinks(dirs[i]) << 1
   | (hf_side(points[i]) + 1) << 2 | hf_unreachable(points[i], dirs[i]) << 4. */
__kernel void heightfield_predicates(__global const HeightField* restrict hf,
                                     __global const float4* restrict verts,
                                     __global const float4* restrict points,
                                     __global const float4* restrict dirs,
                                     __global int* restrict out, const int n)
{
    const int i = get_global_id(0);
    if (i >= n) return;
    const float3 o = points[i].xyz, d = dirs[i].xyz;
    out[i] = (int)hf_climbs(hf, d) | (int)hf_sinks(hf, d) << 1
             | (hf_side(hf, verts, o) + 1) << 2 | (int)hf_unreachable(hf, verts, o, d) << 4;
}
