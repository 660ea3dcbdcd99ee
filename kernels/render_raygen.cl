/* Renderer stage 1: primary rays of one chunk of pixels, in tile (or row) order, spp per pixel.
 * Ray i covers pixel q = q0 + i / spp, sample i % spp; padding pixels outside the image get a
 * dead ray (zero direction and weight) so the wavefront stays sorted by q. */
#include "common.h"
#include "render_optics.h"

inline Ray primary_ray(__constant const Camera* cam, uint q, uint s)
{
    uint x, y;
    Ray r = {cam->origin.x, cam->origin.y, cam->origin.z, q, 0.0f, 0.0f, 0.0f, RENDER_NO_MEDIUM,
             0.0f, 0.0f, 0.0f, s};
    if (!pixel_of(cam, q, &x, &y)) return r;
    const float2 off = sample_offset(cam, y * cam->width + x, s);
    const float sx = 2.0f * (((float)x + off.x) / (float)cam->width) - 1.0f;
    const float sy = 1.0f - 2.0f * (((float)y + off.y) / (float)cam->height);
    const float3 d = normalize(cam->forward.xyz + sx * cam->right.xyz + sy * cam->up.xyz);
    const float w = 1.0f / (float)cam->spp;
    r.dx = d.x; r.dy = d.y; r.dz = d.z;
    r.wr = w; r.wg = w; r.wb = w;
    return r;
}

/* Also zeroes the frame's stats (rp.zero_stats: the first chunk), the chunk's shadow-list counts
 * (render_shadow_list.cl) and, with rp.zero_light, its pixels' shadow-list light
 * (render_shadow_list.h: coalesced stores beside the rays', where a fill at the frame's start
 * was a launch of its own; on an H100 the same time, 0.022 against 0.023 ms at 1920x1080, a
 * launch fewer: BENCHMARKS.md, fifteenth session); launched with at least RENDER_STATS_LEN
 * work-items. */
__kernel void render_raygen(__constant const Camera* cam, const RaygenParams rp,
                            __global Ray* rays, __global uint* counts, __global uint* stats,
                            __global uint* list_counts, __global ulong* restrict shadow_light)
{
    const uint i = get_global_id(0);
    if (i == 0) counts[0] = rp.n_rays;
    if (rp.zero_stats && i < RENDER_STATS_LEN) stats[i] = 0u;
    if (i < 3) list_counts[i] = 0u;
    if (i >= rp.n_rays) return;
    const uint q = rp.q0 + i / cam->spp, s = i % cam->spp;
    if (rp.zero_light && s == 0) {
        __global ulong* p = shadow_light + 3u * q;
        p[0] = 0ul;
        p[1] = 0ul;
        p[2] = 0ul;
    }
    rays[i] = primary_ray(cam, q, s);
}
