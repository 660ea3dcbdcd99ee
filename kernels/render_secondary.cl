/* Renderer stage: compaction of secondary rays. Each hit's children (reflection, refraction; see
 * spawn_children in render_surface.h) go into the next wavefront at an exclusive prefix sum of
 * the per-ray child counts (no global atomic per ray), which keeps the wavefront sorted by
 * pixel. One launch: every work-group scans its block of RENDER_SCAN_BLOCK counts in place and
 * publishes the block's total; the last block to finish (a ticket, as in CUDA's threadfence
 * reduction) scans the block totals into block offsets and writes the next wavefront's size. The
 * children themselves are written by render_gather (render_frame.cl, scatter_children). */
#include "common.h"
#include "render_types.h"

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

/* child_counts[i] (i < counts[depth]) -> exclusive offsets within its block, in place;
 * block_sums[g] -> exclusive offset of block g; counts[depth + 1] = the total (clamped to the
 * capacity, the excess counted as dropped), which also joins the frame stats. *ticket must be 0
 * on entry and is 0 again on exit. Launched with at least max(1, blocks) work-groups. */
__kernel __attribute__((reqd_work_group_size(RENDER_SCAN_WG, 1, 1)))
void render_scan(__global uint* child_counts, __global uint* counts, const uint depth,
                 const uint capacity, __global uint* block_sums, __global uint* ticket,
                 __global uint* stats)
{
    __local uint tmp[RENDER_SCAN_WG];
    __local uint is_last;
    const uint lid = get_local_id(0), grp = get_group_id(0);
    const uint n = counts[depth];
    /* at least one block, so that an empty wavefront still writes a zero count */
    const uint n_blocks = max(1u, (n + RENDER_SCAN_BLOCK - 1u) / RENDER_SCAN_BLOCK);
    if (grp >= n_blocks) return;                   /* uniform over the work-group */
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
    if (lid == RENDER_SCAN_WG - 1) {
        block_sums[grp] = tmp[lid];
        DEVICE_FENCE();                            /* the total is visible before the ticket */
        is_last = atomic_inc(ticket) == n_blocks - 1u;
        DEVICE_FENCE();
    }
    barrier(CLK_LOCAL_MEM_FENCE | CLK_GLOBAL_MEM_FENCE);
    /* the last block scans the block totals, all of them published by now (a loop of zero
     * trips elsewhere: no barrier inside a branch, which PoCL's work-group loops mishandle) */
    const uint scan_blocks = is_last ? n_blocks : 0u;
    volatile __global uint* bs = block_sums;
    uint carry = 0;
    for (uint b0 = 0; b0 < scan_blocks; b0 += RENDER_SCAN_WG) {
        const uint idx = b0 + lid;
        const uint x = idx < scan_blocks ? bs[idx] : 0u;
        tmp[lid] = x;
        barrier(CLK_LOCAL_MEM_FENCE);
        scan_local(tmp, lid);
        if (idx < scan_blocks) bs[idx] = carry + tmp[lid] - x;
        carry += tmp[RENDER_SCAN_WG - 1];
        barrier(CLK_LOCAL_MEM_FENCE);
    }
    if (scan_blocks > 0u && lid == 0) {
        const uint kept = min(carry, capacity);
        counts[depth + 1] = kept;
        if (depth == 0) stats[0] += n;
        stats[depth + 1] += kept;
        stats[RENDER_STAT_DROPPED] += carry - kept;
        *ticket = 0u;
    }
}
