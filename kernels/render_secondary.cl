/* Renderer stage: secondary rays. Each hit's children (reflection, refraction; see
 * spawn_children in render_surface.h) are compacted into the next wavefront by an exclusive
 * prefix sum of the per-ray child counts (no global atomic per ray), which keeps the wavefront
 * sorted by pixel. Three launches: per-block scan, scan of the block sums, scatter. */
#include "common.h"
#include "render_surface.h"

/* Inclusive Hillis-Steele scan of tmp[0..RENDER_SCAN_WG) in local memory. */
inline void scan_local(__local uint* tmp, uint lid)
{
    for (uint off = 1; off < RENDER_SCAN_WG; off <<= 1) {
        const uint t = lid >= off ? tmp[lid - off] : 0u;
        barrier(CLK_LOCAL_MEM_FENCE);
        tmp[lid] += t;
        barrier(CLK_LOCAL_MEM_FENCE);
    }
}

/* child_counts[i] (i < counts[depth]) -> exclusive offsets within the block of
 * RENDER_SCAN_BLOCK rays, in place; block_sums[g] = the block's total. */
__kernel __attribute__((reqd_work_group_size(RENDER_SCAN_WG, 1, 1)))
void render_scan_blocks(__global uint* child_counts, __global const uint* counts,
                        const uint depth, __global uint* block_sums)
{
    __local uint tmp[RENDER_SCAN_WG];
    const uint lid = get_local_id(0), grp = get_group_id(0);
    const uint n = counts[depth];
    if (grp * RENDER_SCAN_BLOCK >= n) {            /* uniform over the work-group */
        if (lid == 0) block_sums[grp] = 0u;
        return;
    }
    const uint base = grp * RENDER_SCAN_BLOCK + lid * RENDER_SCAN_PER_ITEM;
    uint v[RENDER_SCAN_PER_ITEM];
    uint sum = 0;
    for (uint k = 0; k < RENDER_SCAN_PER_ITEM; k++) {
        v[k] = base + k < n ? child_counts[base + k] : 0u;
        sum += v[k];
    }
    tmp[lid] = sum;
    barrier(CLK_LOCAL_MEM_FENCE);
    scan_local(tmp, lid);
    uint excl = tmp[lid] - sum;
    for (uint k = 0; k < RENDER_SCAN_PER_ITEM; k++) {
        if (base + k < n) child_counts[base + k] = excl;
        excl += v[k];
    }
    if (lid == RENDER_SCAN_WG - 1) block_sums[grp] = tmp[lid];
}

/* One work-group: block_sums -> exclusive offsets; the total becomes the next wavefront's
 * count (clamped to the capacity, the excess counted as dropped) and joins the frame stats. */
__kernel __attribute__((reqd_work_group_size(RENDER_SCAN_WG, 1, 1)))
void render_scan_sums(__global uint* block_sums, const uint n_blocks, __global uint* counts,
                      const uint depth, const uint capacity, __global uint* stats)
{
    __local uint tmp[RENDER_SCAN_WG];
    const uint lid = get_local_id(0);
    uint carry = 0;
    for (uint base = 0; base < n_blocks; base += RENDER_SCAN_WG) {
        const uint idx = base + lid;
        const uint v = idx < n_blocks ? block_sums[idx] : 0u;
        tmp[lid] = v;
        barrier(CLK_LOCAL_MEM_FENCE);
        scan_local(tmp, lid);
        if (idx < n_blocks) block_sums[idx] = carry + tmp[lid] - v;
        carry += tmp[RENDER_SCAN_WG - 1];
        barrier(CLK_LOCAL_MEM_FENCE);
    }
    if (lid == 0) {
        const uint kept = min(carry, capacity);
        counts[depth + 1] = kept;
        if (depth == 0) stats[0] += counts[0];
        stats[depth + 1] += kept;
        stats[RENDER_STAT_DROPPED] += carry - kept;
    }
}

__kernel void render_scatter(RENDER_GEOM_PARAMS, __constant const RenderParams* prm,
                             __global const Ray* rays, __global const Hit* hits,
                             __global const uint* counts, const uint depth,
                             __global const uint* child_offsets,
                             __global const uint* block_sums, __global Ray* out)
{
    const uint i = get_global_id(0);
    GUARD_COUNT(i, counts + depth);
    const Hit h = hits[i];
    if (h.prim < 0) return;
    const Ray r = rays[i];
    const Surface s = surface_at(RENDER_GEOM_ARGS, h.inst, h.prim, h.u, h.v);
    const float3 w = attenuated_weight(&r, h.t, g_mat);
    Ray kids[2];
    const int n = spawn_children(&r, &s, w, depth, prm, g_mat, kids);
    const uint dst = child_offsets[i] + block_sums[i / RENDER_SCAN_BLOCK];
    for (int k = 0; k < n; k++)
        if (dst + (uint)k < prm->capacity) out[dst + (uint)k] = kids[k];
}
