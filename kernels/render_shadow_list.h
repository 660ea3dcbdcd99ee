/* The shadow list's light of each pixel (render_shadow_list.cl): three sums in 64-bit fixed
 * point, 32 bits of them fraction (24 bytes a pixel), that the list's shadow rays add to with
 * atomics. Integer sums are the same in any order, so a pixel's light does not depend on which
 * work-item adds first, nor on whether a ray was listed or spilled; the tonemap pass
 * (render_frame.cl) adds the sum to the framebuffer, and render_raygen zeroes the chunk's sums
 * (zeroing them in the tonemap pass took 0.11 ms more on the H200 at 1920x1080). */
#ifndef LBWATER_RENDER_SHADOW_LIST_H
#define LBWATER_RENDER_SHADOW_LIST_H

#pragma OPENCL EXTENSION cl_khr_int64_base_atomics : enable

#include "render_types.h"

#define SHADOW_LIGHT_ONE 0x1p32f
/* One ray's share at most (linear radiance): sums of up to 2^20 of them stay below 2^64. */
#define SHADOW_LIGHT_MAX 4096.0f

inline void shadow_light_add(__global ulong* restrict light, uint q, float3 c)
{
    const float3 f = clamp(c, 0.0f, SHADOW_LIGHT_MAX) * SHADOW_LIGHT_ONE;
    __global ulong* p = light + 3u * q;
    if (f.x >= 0.5f) atom_add(p, convert_ulong_rte(f.x));
    if (f.y >= 0.5f) atom_add(p + 1, convert_ulong_rte(f.y));
    if (f.z >= 0.5f) atom_add(p + 2, convert_ulong_rte(f.z));
}

/* Pixel q's sum as linear radiance. */
inline float3 shadow_light_of(__global const ulong* restrict light, uint q)
{
    __global const ulong* p = light + 3u * q;
    return (float3)(convert_float(p[0]), convert_float(p[1]), convert_float(p[2]))
           * (1.0f / SHADOW_LIGHT_ONE);
}

#endif
