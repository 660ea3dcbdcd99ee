/* Device writers of the scene's transform buffer (kernels/transform.h). One launch of one
   work-item per row it changes; no host copy. The TLAS build reads the rows at the next update.
     transform_compose: rows[row] = delta * rows[row] (delta applied in world space after the
                        instance's own world_from_object), e.g. a pose integrated on the device. */
#include "transform.h"

__kernel void transform_compose(__global Transform* rows, const int row, const Transform delta)
{
    if (get_global_id(0) != 0) return;
    const Transform m = rows[row];
    /* (D * M) with D, M affine 3x4: linear parts multiply, D's translation adds */
    const float4 c0 = (float4)(m.r0.x, m.r1.x, m.r2.x, 0.0f);
    const float4 c1 = (float4)(m.r0.y, m.r1.y, m.r2.y, 0.0f);
    const float4 c2 = (float4)(m.r0.z, m.r1.z, m.r2.z, 0.0f);
    const float4 c3 = (float4)(m.r0.w, m.r1.w, m.r2.w, 1.0f);
    Transform out;
    out.r0 = (float4)(dot(delta.r0, c0), dot(delta.r0, c1), dot(delta.r0, c2), dot(delta.r0, c3));
    out.r1 = (float4)(dot(delta.r1, c0), dot(delta.r1, c1), dot(delta.r1, c2), dot(delta.r1, c3));
    out.r2 = (float4)(dot(delta.r2, c0), dot(delta.r2, c1), dot(delta.r2, c2), dot(delta.r2, c3));
    rows[row] = out;
}
