/* Floating rigid bodies on the shallow water (lbm_bodies.cl, lbm/bodies.py): device structs.
 *
 * A hull is described by a footprint: a grid of nfx x nfz vertical columns in body coordinates
 * (x, z), sample centres at (x0 + ix dfx, z0 + iz dfz), each a float2 (bottom, top): where the
 * closed hull mesh crosses that vertical line (top < bottom: no hull there; such columns ring
 * the hull and measure the water level around it). Body coordinates have their origin at the
 * centre of mass and the hull's rest orientation; quaternions are stored (w, x, y, z).
 */
#ifndef LBWATER_LBM_BODIES_H
#define LBWATER_LBM_BODIES_H

#include "transform.h"

/* Work-group size of lbm_bodies_update (a power of two): G work-groups per body slot (the
 * launch's size says G), each the body's whole update and a tile of its pressure pass. */
#ifndef LBM_BODY_WG   /* lbm/bodies.py Boats(work_group=...) may set it */
#define LBM_BODY_WG 512
#endif
/* Cells per work-item per step of the update's pressure pass, their reads in flight together
 * (lbm/bodies.py Boats(press_batch=...) may set it). */
#ifndef LBM_PRESS_BATCH
#define LBM_PRESS_BATCH 4
#endif
/* Partial sums per accumulator in the update's reduction (LBM_BODY_WG / 32 terms each). */
#define LBM_BODY_PARTS 16
/* Most bodies (lbm/bodies.py MAX_BOATS): the kernels stage them all in local memory. */
#define LBM_MAX_BODIES 16
/* Horizontal speed limit of a body, m/s (lbm/bodies.py MAX_SPEED): it bounds where a body can
 * be at the end of an update, so the update can tell from the start which bodies' cells can
 * meet (those are updated by one work-group; the others each by their own). */
#define LBM_BODY_MAX_SPEED 5

/* 256 bytes: one rigid body, its hull footprint and its transform row. */
typedef struct {
    float4 pos;      /* centre of mass in world coordinates, m; w: mass, kg */
    float4 quat;     /* world_from_body rotation as (w, x, y, z) in (x, y, z, w) */
    float4 vel;      /* velocity of the centre of mass, m/s; w: depth of the hull's lowest
                        point below the centre of mass at rest orientation, m (the floor) */
    float4 omega;    /* angular velocity in world coordinates, rad/s; w: the largest distance
                        of a point where a footprint column samples the water (its bottom;
                        a ring column's centre) from the centre of mass, m */
    float4 inertia;  /* principal moments about the centre of mass (body x, y, z), kg m^2;
                        w: added mass as a fraction of the mass (and of the inertia) */
    float4 damping;  /* rates, 1/s: x heave, y drift (relative to the water), z rotation;
                        w: walls' half extent of the hull in the plane (its bounding radius), m */
    float4 force;    /* last hydrodynamic force on the body, N; w: submerged volume, m^3 */
    float4 torque;   /* last hydrodynamic torque about the centre of mass, N m;
                        w: water level around the hull (mean head of the ring columns), m */
    float4 base_r0;  /* body_from_mesh, a 3x4 affine (rows): the mesh's own placement */
    float4 base_r1;
    float4 base_r2;
    float4 foot;     /* footprint: x0, z0 (first sample centre, body m), dfx, dfz (m) */
    int4 foot_n;     /* nfx, nfz, offset of the first column in the footprint array, row of
                        the transform buffer this body writes */
    int4 flags;      /* x: 1 active; y: 1 held (the pose stays, at rest; the hull still
                        presses on the water); z, w: columns, rows of the footprint
                        that are empty on each side (its ring, at least) */
    int4 box;        /* cells (i0, j0, i1, j1), inclusive, holding every cell the pressure head
                        of the pose last pressed can cover (the footprint where it meets the
                        still water, within the bounding circle), one cell of margin (set by
                        the bodies update) */
    int4 box_old;    /* the box of the pose pressed before: the update restored it */
} LbmBody;

/* 48 bytes: one bodies step, by value. */
typedef struct {
    float4 origin;   /* world position of the water grid's corner (cell (0, 0) at +dx/2), m */
    float dt;        /* s */
    float gravity;   /* m/s^2 */
    float rho;       /* water density, kg/m^3 */
    int n_bodies;
    float size_x;    /* extent of the water box along world x and z, m (walls) */
    float size_z;
    float floor;     /* lowest bed height, m above origin.y: no hull goes below it */
    int n_sub;       /* substeps of dt in one launch of lbm_bodies_update */
} LbmBodyStep;

#endif
