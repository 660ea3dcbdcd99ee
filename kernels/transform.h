/* One row of the scene's device transform buffer: an instance's affine world_from_object as three
   float4 rows (48 bytes); point p_world = (r0.xyz.p + r0.w, r1..., r2...). The host writes a row
   when a user moves something; a device stage (floating boats, lbm_bodies.cl) may write rows with
   no host copy. The TLAS build (bvh_tlas.cl) derives each Instance record and the normal
   transform from these rows on the device. Mirrored by raytrace.scene.TRANSFORM_DTYPE. */
#ifndef LBWATER_TRANSFORM_H
#define LBWATER_TRANSFORM_H

typedef struct {
    float4 r0;
    float4 r1;
    float4 r2;
} Transform;

#endif
