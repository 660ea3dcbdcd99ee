/* Caustics: the by-value parameters of the caustics launches (and of render_shadow, which reads
 * the map) and the texel atlas over the pool's diffuse surfaces. Mirrored by
 * raytrace.caustics.CAUSTIC_PARAMS; the layout is proved on the device.
 *
 * The atlas: five faces of the pool box in one array of texels, in this order
 *   0 floor      (normal +y)  u along x, v along z   nx * nz texels
 *   1 z0 wall    (normal +z)  u along x, v along y   nx * ny
 *   2 z1 wall    (normal -z)  u along x, v along y   nx * ny
 *   3 x0 wall    (normal +x)  u along z, v along y   nz * ny
 *   4 x1 wall    (normal -x)  u along z, v along y   nz * ny
 * Texel sizes tx, ty, tz divide the box exactly, so every texel's area is exact. */
#ifndef LBWATER_CAUSTICS_H
#define LBWATER_CAUSTICS_H

#define CAUSTIC_FACES 5
/* A photon meets at most this many surfaces: the water from above, then the receiver. */
#define CAUSTIC_MAX_HITS 3

/* 176 bytes. */
typedef struct {
    float4 box_lo;      /* xyz pool box min corner (m): the floor is y = box_lo.y */
    float4 box_hi;      /* xyz pool box max corner (m): the walls' tops are y = box_hi.y */
    float4 texel;       /* xyz texel size along x, y, z (m); w: W per fixed-point unit */
    float4 emit;        /* photon grid over the water at its rest level: x0, z0, x1, z1 (m) */
    float4 light_dir;   /* xyz unit direction the light travels; w: rest level y of the water */
    float4 flux;        /* rgb flux per photon (W): directional E |d.y| cell area, spot I cell
                           area (times cone |d.y| / dist^2 per photon); w: fixed-point units/W */
    float4 light_pos;   /* xyz spot position (m); w: 1 for a spot (light_dir: its axis), 0 */
    uint nx, ny, nz, n_texels;  /* texels along x, y, z; texels of the atlas */
    uint grid_x, grid_z, seed, fresnel;  /* photon grid; frame's jitter seed; FRESNEL_* */
    int pool_instance;  /* the receiver instance (the pool's floor and walls) */
    uint enabled;       /* 0: render_shadow ignores the map (caustics off) */
    uint light_mask;    /* bit l: light l is carried by the map under the water */
    uint filter_radius; /* tent filter radius (texels), 0: none */
    float blend;        /* weight of last frame's map (0: none, the first frame) */
    float emit_y;       /* height the photons start from (above every surface they can meet) */
    float cos_inner, cos_outer; /* spot cone: full inside inner, smooth to zero at outer */
} CausticParams;

/* Face of a receiver point from its normal facing the incoming ray (or photon); -1: none. */
inline int caustic_face(float3 nf)
{
    if (nf.y > 0.5f) return 0;
    if (nf.z > 0.5f) return 1;
    if (nf.z < -0.5f) return 2;
    if (nf.x > 0.5f) return 3;
    if (nf.x < -0.5f) return 4;
    return -1;
}

/* Face f's texel counts (nu, nv) and its first texel in the atlas. */
inline uint caustic_face_dims(const CausticParams* cp, int f, uint* nu, uint* nv)
{
    const uint floor_n = cp->nx * cp->nz, zwall = cp->nx * cp->ny, xwall = cp->nz * cp->ny;
    if (f == 0) { *nu = cp->nx; *nv = cp->nz; return 0u; }
    if (f <= 2) { *nu = cp->nx; *nv = cp->ny; return floor_n + (uint)(f - 1) * zwall; }
    *nu = cp->nz; *nv = cp->ny;
    return floor_n + 2u * zwall + (uint)(f - 3) * xwall;
}

/* Continuous texel coordinates (u, v) of point p on face f (texel k spans [k, k + 1)). */
inline float2 caustic_uv(const CausticParams* cp, int f, float3 p)
{
    const float3 q = (p - cp->box_lo.xyz) / cp->texel.xyz;
    if (f == 0) return (float2)(q.x, q.z);
    if (f <= 2) return (float2)(q.x, q.y);
    return (float2)(q.z, q.y);
}

/* Area (m^2) of a texel of face f. */
inline float caustic_texel_area(const CausticParams* cp, int f)
{
    if (f == 0) return cp->texel.x * cp->texel.z;
    if (f <= 2) return cp->texel.x * cp->texel.y;
    return cp->texel.z * cp->texel.y;
}

/* The atlas texel holding point p on face f (clamped into the face). */
inline uint caustic_texel(const CausticParams* cp, int f, float3 p)
{
    uint nu, nv;
    const uint off = caustic_face_dims(cp, f, &nu, &nv);
    const float2 uv = caustic_uv(cp, f, p);
    const uint iu = (uint)clamp((int)floor(uv.x), 0, (int)nu - 1);
    const uint iv = (uint)clamp((int)floor(uv.y), 0, (int)nv - 1);
    return off + iv * nu + iu;
}

/* Irradiance (W/m^2, rgb) of the map at p on the face whose normal towards the viewer is nf:
 * bilinear between texel centres inside the face. */
inline float3 caustic_lookup(__global const float4* restrict map, const CausticParams* cp,
                             float3 p, float3 nf)
{
    const int f = caustic_face(nf);
    if (f < 0) return (float3)(0.0f);
    uint nu, nv;
    const uint off = caustic_face_dims(cp, f, &nu, &nv);
    const float2 uv = caustic_uv(cp, f, p) - 0.5f;
    const float x = clamp(uv.x, 0.0f, (float)(nu - 1)), y = clamp(uv.y, 0.0f, (float)(nv - 1));
    const float fx = floor(x), fy = floor(y);
    const float ax = x - fx, ay = y - fy;
    const uint x0 = (uint)fx, y0 = (uint)fy;
    const uint x1 = min(x0 + 1u, nu - 1u), y1 = min(y0 + 1u, nv - 1u);
    const float3 a = map[off + y0 * nu + x0].xyz, b = map[off + y0 * nu + x1].xyz;
    const float3 c = map[off + y1 * nu + x0].xyz, d = map[off + y1 * nu + x1].xyz;
    return (a * (1.0f - ax) + b * ax) * (1.0f - ay) + (c * (1.0f - ax) + d * ax) * ay;
}

#endif
