/* Renderer stage: compaction of secondary rays. Each hit's children (reflection, refraction; see
 * spawn_children in render_surface.h) go into the next wavefront at an exclusive prefix sum of
 * the per-ray child counts (no global atomic per ray), which keeps the wavefront sorted by
 * pixel. One launch: every work-group scans its block of RENDER_SCAN_BLOCK counts in place and
 * publishes the block's total; the last block to finish (a ticket, as in CUDA's threadfence
 * reduction) scans the block totals into block offsets and writes the next wavefront's size. The
 * children themselves are written by render_gather (render_frame.cl, scatter_children). */
#include "common.h"
#include "render_scan.h"

/* One launch of scan_level (render_scan.h). */
__kernel __attribute__((reqd_work_group_size(RENDER_SCAN_WG, 1, 1)))
void render_scan(__global uint* child_counts, __global uint* counts, const uint depth,
                 const uint capacity, __global uint* block_sums, __global uint* ticket,
                 __global uint* stats)
{
    __local uint tmp[RENDER_SCAN_WG];
    __local uint is_last;
    scan_level(child_counts, counts, depth, capacity, block_sums, ticket, stats, tmp, &is_last);
}
