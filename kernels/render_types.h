/* Wavefront renderer: device structs and enums. Each struct has one NumPy mirror in
 * raytrace/render_types.py whose layout a test proves with kernels/layout.check_struct. */
#ifndef LBWATER_RENDER_TYPES_H
#define LBWATER_RENDER_TYPES_H

#define RENDER_MAX_LIGHTS 8
#define RENDER_NO_MEDIUM (-1)
#define RENDER_DEAD_PIXEL 0xffffffffu
/* Tiles of 8x8 pixels, Morton order inside a tile. */
#define RENDER_TILE_BITS 3
#define RENDER_TILE 8
/* Scan: work-group size and elements per work-item (one block = 1024 counts). */
#define RENDER_SCAN_WG 256
#define RENDER_SCAN_PER_ITEM 4
#define RENDER_SCAN_BLOCK (RENDER_SCAN_WG * RENDER_SCAN_PER_ITEM)
/* Shadow rays cross at most this many transmissive (dielectric) surfaces; more means dark. */
#define RENDER_MAX_SHADOW_CROSSINGS 4
/* Instance visibility bits (kernels/bvh.h Instance.mask, set by RenderScene): every triangle
   opaque, or some dielectric (water, glass); each instance has exactly one. */
#define RENDER_MASK_OPAQUE 1u
#define RENDER_MASK_TRANSMISSIVE 2u

/* enum SamplePattern */
#define SAMPLE_CENTER 0
#define SAMPLE_RGSS 1
#define SAMPLE_JITTERED 2
/* enum PixelOrder */
#define ORDER_ROWS 0
#define ORDER_TILES 1
/* enum FresnelMode */
#define FRESNEL_EXACT 0
#define FRESNEL_SCHLICK 1
/* enum LightKind */
#define LIGHT_DIRECTIONAL 0
#define LIGHT_SPOT 1
/* enum SkyKind */
#define SKY_PROCEDURAL 0
#define SKY_CUBEMAP 1
/* enum Tonemap */
#define TONEMAP_CLAMP 0
#define TONEMAP_REINHARD 1
#define TONEMAP_ACES 2
/* MeshInfo.flags */
#define MESH_HAS_NORMALS 1u
#define MESH_HAS_UVS 2u
#define MESH_TRI_MATERIALS 4u
#define MESH_DYNAMIC 8u       /* positions/normals in the dynamic arrays (g_dpos, g_dnrm) */
/* Depth limit and the stats buffer: stats[d] = rays traced at depth d over the frame,
 * stats[RENDER_STAT_DROPPED] = children dropped because the wavefront was full; with the shadow
 * list (render_shadow_list.cl), the shadow rays it traced and those spilled for want of room
 * (traced by their level's render_shadow_spill). */
#define RENDER_MAX_DEPTH 32
#define RENDER_STAT_DROPPED (RENDER_MAX_DEPTH + 1)
#define RENDER_STAT_SHADOW_LISTED (RENDER_MAX_DEPTH + 2)
#define RENDER_STAT_SHADOW_SPILLED (RENDER_MAX_DEPTH + 3)
#define RENDER_STATS_LEN (RENDER_MAX_DEPTH + 4)
/* A shadow-list entry's pixel field: the tile-order pixel q (< 2^28: 16384^2 pixels) and, above
   it, the light's index (< RENDER_MAX_LIGHTS). */
#define SHADOW_RAY_LIGHT_SHIFT 28
#define SHADOW_RAY_PIXEL_MASK ((1u << SHADOW_RAY_LIGHT_SHIFT) - 1u)

/* 48 bytes: three float4 rows, 16-byte aligned so a ray moves as three vector loads/stores.
 * One wavefront entry. */
typedef struct __attribute__((aligned(16))) {
    float ox, oy, oz;   /* origin (m), already offset off the surface it left */
    uint pixel;         /* tile-order pixel id q; rays stay sorted by it */
    float dx, dy, dz;   /* unit direction; all zero for a dead (padding) ray */
    int medium;         /* material id of the dielectric the ray travels in, -1: air */
    float wr, wg, wb;   /* contribution weight per channel, <= 1 */
    uint sample;        /* primary sample index within its pixel (for AOVs) */
} Ray;

/* 32 bytes: two float4 rows, 16-byte aligned. One shadow ray of the shadow list
 * (render_shadow_list.cl): where it starts and what the light adds to its pixel when nothing
 * blocks it; its direction and length follow from the origin and the light (shadow_ray_toward:
 * render_shadow.h), so the entry leaves them out (48 bytes with them). */
typedef struct __attribute__((aligned(16))) {
    float ox, oy, oz;   /* origin (m), already offset off the surface */
    uint pixel_light;   /* q | light << SHADOW_RAY_LIGHT_SHIFT */
    float cr, cg, cb;   /* the light's unshadowed share of the pixel: w E brdf */
    int medium;         /* material id of the dielectric the ray starts in, -1: air */
} ShadowRay;

/* 16 bytes. The shadow list's per-launch values: its two parts' room in entries. The list holds
 * main_room entries, then full_room for the rays that start in a full light-buffer cell (traced
 * first: the costliest). */
typedef struct {
    uint main_room, full_room;
    uint pad0, pad1;
} ShadowListParams;

/* 96 bytes. Pinhole camera; basis vectors already scaled by the image-plane extent. */
typedef struct {
    float4 origin;      /* xyz eye (m) */
    float4 right;       /* xyz: right * tan(fov/2) * aspect */
    float4 up;          /* xyz: up * tan(fov/2) */
    float4 forward;     /* xyz: unit view direction */
    uint width, height, spp, pattern;
    uint order, tiles_x, jitter_cols, seed;
} Camera;

/* 64 bytes. */
typedef struct {
    float4 diffuse;     /* rgb linear albedo; w unused */
    float4 specular;    /* rgb Phong specular colour; w shininess exponent */
    float4 absorption;  /* rgb Beer-Lambert coefficient inside (1/m); w: IOR, 0 for opaque */
    float reflectivity; /* opaque: fraction reflected as a mirror, 0..1 */
    int texture;        /* index into TexInfo table, -1: none */
    float uv_scale_u, uv_scale_v;
} Material;

/* 64 bytes. */
typedef struct {
    float4 position;    /* xyz spot position (m) */
    float4 direction;   /* xyz unit direction the light travels */
    float4 color;       /* rgb radiance scale: irradiance (directional), intensity (spot) */
    int kind;           /* LIGHT_DIRECTIONAL or LIGHT_SPOT */
    float cos_inner, cos_outer; /* spot cone: full inside inner, smooth to zero at outer */
    float pad;
} Light;

/* 16 bytes. A texture in the texel pool (float4 linear RGBA, row-major, row 0 = v 0). */
typedef struct {
    uint offset, width, height, pad;
} TexInfo;

/* 16 bytes. A mesh's range in the concatenated geometry arrays. */
typedef struct {
    uint vert_offset, tri_offset;
    int material;       /* default material id */
    uint flags;         /* MESH_* */
} MeshInfo;

/* 16 bytes. What an instance draws; its transforms live once, in the scene's transform buffer
 * (g_xform) and the normal rows the TLAS build derives from it (g_nxform). */
typedef struct {
    uint mesh;
    int material;       /* overrides the mesh's materials when >= 0 */
    uint pad0, pad1;
} InstanceInfo;

/* 160 bytes. Per-frame shading settings. */
typedef struct {
    float4 ambient;     /* rgb ambient light */
    float4 sky_zenith;  /* rgb */
    float4 sky_horizon; /* rgb */
    float4 sky_ground;  /* rgb */
    float4 sun_dir;     /* xyz unit direction towards the sun; w: cos of the sun's radius */
    float4 sun_color;   /* rgb sun disk radiance; w: glow strength */
    float4 exposure;    /* x exposure multiplier */
    uint n_lights, fresnel, sky, cubemap_tex;
    uint transmissive_shadows, tonemap, max_depth, capacity;
    float min_weight;
    int crossing_instance; /* the one instance holding the dielectrics, else -1 (render_shadow.h) */
    uint one_crossing;  /* 1: where crossing_instance is the height field, rays that climb
                           faster than its slopes cross it at most once (render_shadow.h) */
    float pad2;
} RenderParams;

/* 16 bytes. render_raygen's per-launch values: the chunk it starts. */
typedef struct {
    uint q0;            /* first tile-order pixel of the chunk */
    uint n_rays;        /* primary rays of the chunk (pixels x spp) */
    uint zero_stats;    /* 1 on the frame's first chunk: zero the stats */
    uint zero_light;    /* 1 with the shadow list: zero the chunk's pixels' light */
} RaygenParams;

/* 20 bytes. render_gather's per-launch values: what this level of this chunk does. */
typedef struct {
    uint scatter;       /* 1: scatter the rays' children into the next wavefront */
    uint accumulate;    /* 1: add each pixel's run of rays' radiance into the framebuffer */
    uint q0;            /* first tile-order pixel of the chunk */
    uint n_q;           /* pixels of the chunk */
    uint finish;        /* the tonemap pass after the chunk's last level (no rays): 1, or
                           GATHER_FINISH_SHADOW_LIST: the shadow list's light added first */
} GatherParams;
#define GATHER_FINISH_SHADOW_LIST 2u

/* 32 bytes. Primary-hit outputs per pixel (sample 0 of the pixel). */
typedef struct {
    float4 normal;      /* xyz world shading normal facing the camera, 0 on a miss */
    float depth;        /* distance along the unit camera ray (m), inf on a miss */
    int prim;           /* triangle index within its mesh, -1 on a miss */
    int inst;           /* instance id, -1 on a miss */
    int material;
} Aov;

#endif
