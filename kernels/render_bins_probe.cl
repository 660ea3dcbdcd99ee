/* Test kernel of render_bins.h (tests/raytrace/test_render_bins.py): the binned kernels' loop
   with given classes; out[base + l] = the entry work-item l of the round at base handles. */
#include "render_bins.h"

__kernel __attribute__((reqd_work_group_size(RENDER_BIN_WG, 1, 1))) void render_bins_probe(
    __global const uint* restrict classes, const uint n, __global uint* restrict out)
{
    __local RenderBins bins;
    for (uint base = get_group_id(0) * RENDER_BIN_WG; base < n;
         base += get_num_groups(0) * RENDER_BIN_WG) {
        const uint j = base + get_local_id(0);
        const uint i = bin_round(&bins, j, j < n ? classes[j] : RENDER_BIN_IDLE);
        out[j] = i;   /* out holds every round's RENDER_BIN_WG slots */
    }
}
