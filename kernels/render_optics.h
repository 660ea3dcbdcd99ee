/* Renderer device functions without scene access: hashing and sampling, Snell, Fresnel,
 * Beer-Lambert, robust ray offsets, sky, textures, tonemap. float64 mirrors live in
 * raytrace/render_reference.py. */
#ifndef LBWATER_RENDER_OPTICS_H
#define LBWATER_RENDER_OPTICS_H

#include "render_types.h"

/* ---- hashing (lowbias32, Wellons) and stratified samples -------------------------------- */
inline uint hash_u32(uint x)
{
    x ^= x >> 16;
    x *= 0x7feb352du;
    x ^= x >> 15;
    x *= 0x846ca68bu;
    x ^= x >> 16;
    return x;
}

/* A float in [0, 1) with 24 random bits. */
inline float hash_unit(uint x) { return (float)(hash_u32(x) >> 8) * (1.0f / 16777216.0f); }

/* Offset in [0,1)^2 of sample s of a pixel (pattern of Camera.pattern). */
inline float2 sample_offset(__constant const Camera* cam, uint pixel_index, uint s)
{
    if (cam->pattern == SAMPLE_CENTER) return (float2)(0.5f, 0.5f);
    if (cam->pattern == SAMPLE_RGSS) {
        /* rotated grid: x strata 1,3,0,2 over y strata 0,1,2,3 (quarters, centred) */
        const float xs[4] = {0.375f, 0.875f, 0.125f, 0.625f};
        return (float2)(xs[s & 3u], 0.125f + 0.25f * (float)(s & 3u));
    }
    const uint cols = cam->jitter_cols;
    const uint rows = cam->spp / cols;
    const uint key = hash_u32(pixel_index * 0x9e3779b9u ^ hash_u32(s + cam->seed * 0x85ebca6bu));
    const float jx = hash_unit(key);
    const float jy = hash_unit(key ^ 0x68e31da4u);
    return (float2)(((float)(s % cols) + jx) / (float)cols, ((float)(s / cols) + jy) / (float)rows);
}

/* Tile-order pixel id q -> image (x, y); false for padding outside the image. */
inline bool pixel_of(__constant const Camera* cam, uint q, uint* x, uint* y)
{
    if (cam->order == ORDER_ROWS) {
        *x = q % cam->width;
        *y = q / cam->width;
    } else {
        const uint tile = q >> (2 * RENDER_TILE_BITS);
        uint m = q & (RENDER_TILE * RENDER_TILE - 1u);
        uint mx = 0, my = 0;
        for (uint b = 0; b < RENDER_TILE_BITS; b++) {
            mx |= ((m >> (2 * b)) & 1u) << b;
            my |= ((m >> (2 * b + 1)) & 1u) << b;
        }
        *x = (tile % cam->tiles_x) * RENDER_TILE + mx;
        *y = (tile / cam->tiles_x) * RENDER_TILE + my;
    }
    return *x < cam->width && *y < cam->height;
}

/* ---- reflection, refraction, Fresnel ------------------------------------------------------ */
inline float3 reflect_dir(float3 d, float3 n) { return d - 2.0f * dot(d, n) * n; }

/* Snell: unit d through unit n facing the incoming side (dot(d, n) < 0), eta = n_from / n_to.
 * False on total internal reflection. */
inline bool refract_dir(float3 d, float3 n, float eta, float3* t)
{
    const float cosi = -dot(d, n);
    const float sin2t = eta * eta * fmax(0.0f, 1.0f - cosi * cosi);
    if (sin2t >= 1.0f) return false;
    const float cost = sqrt(1.0f - sin2t);
    *t = normalize(eta * d + (eta * cosi - cost) * n);
    return true;
}

/* Unpolarised reflectance of a dielectric interface; cosi in [0,1], eta = n_from / n_to. */
inline float fresnel_exact(float cosi, float eta)
{
    const float sin2t = eta * eta * fmax(0.0f, 1.0f - cosi * cosi);
    if (sin2t >= 1.0f) return 1.0f;
    const float cost = sqrt(1.0f - sin2t);
    const float rs = (eta * cosi - cost) / (eta * cosi + cost);
    const float rp = (cosi - eta * cost) / (cosi + eta * cost);
    return 0.5f * (rs * rs + rp * rp);
}

/* Schlick's approximation, with the transmitted cosine when leaving the denser medium. */
inline float fresnel_schlick(float cosi, float eta)
{
    float r0 = (eta - 1.0f) / (eta + 1.0f);
    r0 *= r0;
    float c = cosi;
    if (eta > 1.0f) {
        const float sin2t = eta * eta * fmax(0.0f, 1.0f - cosi * cosi);
        if (sin2t >= 1.0f) return 1.0f;
        c = sqrt(1.0f - sin2t);
    }
    const float m = 1.0f - c;
    return r0 + (1.0f - r0) * (m * m) * (m * m) * m;
}

inline float fresnel(uint mode, float cosi, float eta)
{
    return mode == FRESNEL_SCHLICK ? fresnel_schlick(cosi, eta) : fresnel_exact(cosi, eta);
}

/* Beer-Lambert transmittance over distance t (m); t may be huge (a miss): no NaN for sigma 0. */
inline float3 beer(float3 sigma, float t) { return exp(-sigma * fmin(t, 1e30f)); }

/* ---- robust secondary-ray origins (Waechter & Binder 2019, Ray Tracing Gems ch. 6) -------- */
/* p: point on the surface, n: geometric normal on the side the new ray leaves to. */
inline float3 offset_ray(float3 p, float3 n)
{
    const float origin = 1.0f / 32.0f;
    const float float_scale = 1.0f / 65536.0f;
    const float int_scale = 256.0f;
    const int3 of_i = convert_int3_rtz(int_scale * n);
    const int3 pi = as_int3(p) + select(of_i, -of_i, isless(p, (float3)(0.0f)));
    const float3 p_i = as_float3(pi);
    return (float3)(fabs(p.x) < origin ? p.x + float_scale * n.x : p_i.x,
                    fabs(p.y) < origin ? p.y + float_scale * n.y : p_i.y,
                    fabs(p.z) < origin ? p.z + float_scale * n.z : p_i.z);
}

/* ---- textures ------------------------------------------------------------------------------ */
inline float4 texel(__global const float4* texels, TexInfo ti, int x, int y)
{
    return texels[ti.offset + (uint)y * ti.width + (uint)x];
}

/* Bilinear lookup at uv (row 0 is v = 0); wrap repeats, otherwise clamps to the edge. */
inline float4 tex_bilinear(__global const float4* texels, TexInfo ti, float2 uv, bool wrap)
{
    if (wrap) uv -= floor(uv);
    else uv = clamp(uv, 0.0f, 1.0f);
    const int w = (int)ti.width, h = (int)ti.height;
    const float x = uv.x * (float)w - 0.5f, y = uv.y * (float)h - 0.5f;
    const float fx = floor(x), fy = floor(y);
    const float ax = x - fx, ay = y - fy;
    int x0 = (int)fx, y0 = (int)fy, x1 = x0 + 1, y1 = y0 + 1;
    if (wrap) {
        x0 = (x0 + w) % w; x1 = x1 % w; y0 = (y0 + h) % h; y1 = y1 % h;
    } else {
        x0 = clamp(x0, 0, w - 1); x1 = clamp(x1, 0, w - 1);
        y0 = clamp(y0, 0, h - 1); y1 = clamp(y1, 0, h - 1);
    }
    const float4 a = texel(texels, ti, x0, y0), b = texel(texels, ti, x1, y0);
    const float4 c = texel(texels, ti, x0, y1), d = texel(texels, ti, x1, y1);
    return (a * (1.0f - ax) + b * ax) * (1.0f - ay) + (c * (1.0f - ax) + d * ax) * ay;
}

/* ---- sky --------------------------------------------------------------------------------- */
inline float3 sky_procedural(float3 d, __constant const RenderParams* prm)
{
    float3 c;
    if (d.y >= 0.0f)
        c = prm->sky_horizon.xyz + (prm->sky_zenith.xyz - prm->sky_horizon.xyz) * sqrt(d.y);
    else
        c = prm->sky_horizon.xyz + (prm->sky_ground.xyz - prm->sky_horizon.xyz)
            * fmin(1.0f, -10.0f * d.y);
    const float cs = dot(d, prm->sun_dir.xyz);
    if (cs >= prm->sun_dir.w) c += prm->sun_color.xyz;
    const float g = fmax(cs, 0.0f);
    const float g2 = g * g, g4 = g2 * g2, g8 = g4 * g4, g16 = g8 * g8, g32 = g16 * g16;
    c += prm->sun_color.xyz * (prm->sun_color.w * g32 * g32);
    return c;
}

/* Six faces +x -x +y -y +z -z at texture ids cubemap_tex..+5 (OpenGL face conventions). */
inline float3 sky_cubemap(float3 d, __constant const RenderParams* prm,
                          __global const TexInfo* textures, __global const float4* texels)
{
    const float3 a = fabs(d);
    uint face;
    float sc, tc, ma;
    if (a.x >= a.y && a.x >= a.z) {
        face = d.x >= 0.0f ? 0u : 1u; ma = a.x; sc = d.x >= 0.0f ? -d.z : d.z; tc = -d.y;
    } else if (a.y >= a.z) {
        face = d.y >= 0.0f ? 2u : 3u; ma = a.y; sc = d.x; tc = d.y >= 0.0f ? d.z : -d.z;
    } else {
        face = d.z >= 0.0f ? 4u : 5u; ma = a.z; sc = d.z >= 0.0f ? d.x : -d.x; tc = -d.y;
    }
    /* faces are stored bottom row first like every texture: flip t */
    const float2 uv = (float2)(0.5f * (sc / ma + 1.0f), 1.0f - 0.5f * (tc / ma + 1.0f));
    return tex_bilinear(texels, textures[prm->cubemap_tex + face], uv, false).xyz;
}

/* ---- tonemap and sRGB ---------------------------------------------------------------------- */
inline float3 tonemap(float3 c, uint op)
{
    c = fmax(c, 0.0f);
    if (op == TONEMAP_REINHARD) return c / (1.0f + c);
    if (op == TONEMAP_ACES)
        return clamp((c * (2.51f * c + 0.03f)) / (c * (2.43f * c + 0.59f) + 0.14f), 0.0f, 1.0f);
    return clamp(c, 0.0f, 1.0f);
}

inline float srgb_encode(float c)
{
    return c <= 0.0031308f ? 12.92f * c : 1.055f * pow(c, 1.0f / 2.4f) - 0.055f;
}

inline uchar to_u8(float c) { return (uchar)(clamp(c, 0.0f, 1.0f) * 255.0f + 0.5f); }

#endif
