/* Renderer: a work-group's entries handed to its work-items grouped by cost class
 * (RenderSettings.cost_bins), for the *_binned shadow kernels.
 *
 * A level's rays stay sorted by pixel, so neighbours differ in cost: the children of a water
 * hit alternate reflection (mostly sky: no shadow ray) and refraction (the floor under the
 * water: an any-hit query and two closest-hit crossings of the surface). A SIMT machine runs a
 * warp for as long as its costliest lane, so such a warp does the refraction's work at half its
 * width. Here each round of RENDER_BIN_WG entries is reordered inside the work-group by class
 * (through local memory: a count per class, then a slot per entry), so that whole warps take
 * the costly entries and the idle ones retire at once. Which work-item handles an entry never
 * changes its result (each entry is written by the one work-item that has it), so the bytes are
 * those of the unbinned kernels. Local memory: RENDER_BIN_WG + RENDER_BINS uints (1 KiB).
 * A round costs three barriers and bigger work-groups balance a level of few rays worse over
 * the multiprocessors, so the renderer bins only levels of many rays (raytrace.render
 * BIN_MIN_RAYS). */
#ifndef LBWATER_RENDER_BINS_H
#define LBWATER_RENDER_BINS_H

#include "caustics.h"
#include "render_types.h"
#include "scene.h"

#define RENDER_BIN_WG 256      /* work-items of a binned kernel's work-group */
#define RENDER_BINS 5          /* cost classes, costliest first */
#define RENDER_BIN_CROSSING 0u /* shadow rays from inside a dielectric: any-hit + 2 crossings */
#define RENDER_BIN_SHADOW 1u   /* other shadow rays: an any-hit query (+ a crossing query) */
#define RENDER_BIN_TRACE 2u    /* closest-hit rays of the next level (render_shadow_trace) */
#define RENDER_BIN_LOOKUP 3u   /* every light from the caustic map: no traversal */
#define RENDER_BIN_IDLE 4u     /* no work: a miss, no lights, past the count */

typedef struct {
    uint count[RENDER_BINS];
    uint order[RENDER_BIN_WG];
} RenderBins;

/* The entry this work-item handles in a round: the round's entries ``j`` (one per work-item, of
 * class ``cls``) ordered by class. Every work-item of the group calls it, the same number of
 * times (it holds barriers). */
inline uint bin_round(__local RenderBins* b, const uint j, const uint cls)
{
    const uint lid = get_local_id(0);
    if (lid < RENDER_BINS) b->count[lid] = 0u;
    barrier(CLK_LOCAL_MEM_FENCE);
    const uint slot = atomic_inc(&b->count[cls]);
    barrier(CLK_LOCAL_MEM_FENCE);
    uint first = 0u;
    for (uint c = 0u; c < cls; c++) first += b->count[c];
    b->order[first + slot] = j;
    barrier(CLK_LOCAL_MEM_FENCE);
    return b->order[lid];   /* read before the next round's first barrier: no race */
}

/* The cost class of shadow entry i (render_shadow.h shadow_ray): by the traversal queries its
 * lights take. Inside a dielectric, in a scene with transmissive shadows, a light goes through
 * the caustic map (none: RENDER_BIN_LOOKUP when every light does) or crosses the surface. */
inline uint shadow_cost_class(__constant const RenderParams* prm,
                              __global const Ray* restrict rays,
                              __global const Hit* restrict hits, const uint i,
                              const CausticParams* cp)
{
    const Hit h = hits[i];
    if (h.prim < 0 || prm->n_lights == 0) return RENDER_BIN_IDLE;
    const int medium = rays[i].medium;
    if (medium < 0 || !prm->transmissive_shadows) return RENDER_BIN_SHADOW;
    const bool caustic = cp->enabled && h.inst == cp->pool_instance;
    const uint all = prm->n_lights >= 32u ? ~0u : (1u << prm->n_lights) - 1u;
    if (caustic && (cp->light_mask & all) == all) return RENDER_BIN_LOOKUP;
    return RENDER_BIN_CROSSING;
}

/* The cost class of entry j of a combined launch (render_shadow_trace_binned): level
 * depth - 1's n_shadow shadow rays first, then level depth's traces, up to n. */
inline uint shadow_trace_cost_class(__constant const RenderParams* prm,
                                    __global const Ray* restrict shadow_rays,
                                    __global const Hit* restrict shadow_hits, const uint j,
                                    const uint n_shadow, const uint n, const CausticParams* cp)
{
    if (j >= n) return RENDER_BIN_IDLE;
    if (j >= n_shadow) return RENDER_BIN_TRACE;
    return shadow_cost_class(prm, shadow_rays, shadow_hits, j, cp);
}

#endif
