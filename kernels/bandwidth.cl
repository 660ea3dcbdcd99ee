/* Device copy bandwidth: the ceiling that memory-bound stages (LBM, refit) are measured against. */
#include "common.h"

/* 16-byte loads and stores, one float4 per work-item. */
__kernel void copy_float4(__global const float4* restrict src, __global float4* restrict dst,
                          const uint n)
{
    const uint i = get_global_id(0);
    if (i < n) dst[i] = src[i];
}
