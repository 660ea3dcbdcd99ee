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

inline float3 xform_point(const Transform m, float3 p)
{
    return (float3)(dot(m.r0.xyz, p) + m.r0.w, dot(m.r1.xyz, p) + m.r1.w,
                    dot(m.r2.xyz, p) + m.r2.w);
}

inline float3 xform_vector(const Transform m, float3 v)
{
    return (float3)(dot(m.r0.xyz, v), dot(m.r1.xyz, v), dot(m.r2.xyz, v));
}

#endif
