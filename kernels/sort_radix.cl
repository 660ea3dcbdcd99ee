/* Least-significant-digit radix sort of (uint key, uint value) pairs, RADIX_BITS (4 or 8) per
   pass (raytrace.sort.RadixSorter). One pass is three launches:
     radix_histogram : digit counts per tile -> counts[digit * n_tiles + tile]
     radix_scan      : exclusive scan of counts (one work-group), giving each (digit, tile) its
                       first output position
     radix_scatter   : the tile sorted stably by the digit in local memory (one 4-bit split per
                       4 bits of digit: per-thread packed counts and a local scan), then written
                       out in runs of equal digits
   With few tiles (fused = 1) radix_scatter sums the raw counts itself and the scan launch is
   skipped: two launches per pass instead of three, which is what small inputs pay for (8-bit
   digits halve the passes again: see RadixSorter for which width is used where).
   A tile is RADIX_WG threads x RADIX_ITEMS keys. The sort is stable, so the passes compose. */

#ifndef RADIX_WG
#define RADIX_WG 256
#endif
#ifndef RADIX_ITEMS
#define RADIX_ITEMS 8
#endif
#ifndef RADIX_BITS
#define RADIX_BITS 4
#endif
#if RADIX_BITS != 4 && RADIX_BITS != 8
#error "RADIX_BITS must be 4 or 8"
#endif
#define RADIX (1 << RADIX_BITS)
#define RADIX_TILE (RADIX_WG * RADIX_ITEMS)
#define SPLIT_BITS 4
#define SPLIT (1 << SPLIT_BITS)
#ifndef SCAN_WG
#define SCAN_WG 256
#endif

/* Per-thread counts of 4-bit digits packed 4 bits per digit (RADIX_ITEMS <= 15) in a ulong. */
inline uint packed_count(ulong packed, uint d) {
    return (uint)(packed >> (4 * d)) & 15u;
}

inline uint digit_of(uint key, uint shift) {
    return (key >> shift) & (RADIX - 1);
}

/* Exclusive scan over the `width` values `v` (one per thread of a work-group of that size);
   returns this thread's prefix and the total through *total. Hillis-Steele in local memory. */
inline uint wg_exclusive_scan(uint v, __local uint* tmp, int width, uint* total) {
    int lid = get_local_id(0);
    tmp[lid] = v;
    barrier(CLK_LOCAL_MEM_FENCE);
    for (int off = 1; off < width; off <<= 1) {
        uint add = lid >= off ? tmp[lid - off] : 0u;
        barrier(CLK_LOCAL_MEM_FENCE);
        tmp[lid] += add;
        barrier(CLK_LOCAL_MEM_FENCE);
    }
    *total = tmp[width - 1];
    uint incl = tmp[lid];
    barrier(CLK_LOCAL_MEM_FENCE);
    return incl - v;
}

__kernel __attribute__((reqd_work_group_size(RADIX_WG, 1, 1)))
void radix_histogram(uint n, uint shift, __global const uint* restrict keys,
                     __global uint* restrict counts, uint n_tiles) {
    int lid = get_local_id(0);
    uint tile = get_group_id(0);
    uint base = tile * RADIX_TILE;
#if RADIX_BITS == 4
    __local uint part[RADIX * RADIX_WG];
    ulong packed = 0;
    for (int k = 0; k < RADIX_ITEMS; ++k) {
        uint j = base + k * RADIX_WG + lid;
        if (j < n) packed += 1ul << (4 * digit_of(keys[j], shift));
    }
    for (int d = 0; d < RADIX; ++d) part[d * RADIX_WG + lid] = packed_count(packed, d);
    barrier(CLK_LOCAL_MEM_FENCE);
    /* tree reduction of each digit's RADIX_WG counts */
    for (int s = RADIX_WG / 2; s > 0; s >>= 1) {
        if (lid < s)
            for (int d = 0; d < RADIX; ++d) part[d * RADIX_WG + lid] += part[d * RADIX_WG + lid + s];
        barrier(CLK_LOCAL_MEM_FENCE);
    }
    if (lid < RADIX) counts[lid * n_tiles + tile] = part[lid * RADIX_WG];
#else
    /* 256 bins: local atomics, one per run of equal digits among a thread's consecutive keys
       (Morton keys of a mesh come in long runs in the high digits, so few atomics collide) */
    __local uint bins[RADIX];
    for (int d = lid; d < RADIX; d += RADIX_WG) bins[d] = 0;
    barrier(CLK_LOCAL_MEM_FENCE);
    uint run_digit = 0, run = 0;
    for (int k = 0; k < RADIX_ITEMS; ++k) {
        uint j = base + lid * RADIX_ITEMS + k;
        if (j < n) {
            uint d = digit_of(keys[j], shift);
            if (run && d != run_digit) {
                atomic_add(&bins[run_digit], run);
                run = 0;
            }
            run_digit = d;
            ++run;
        }
    }
    if (run) atomic_add(&bins[run_digit], run);
    barrier(CLK_LOCAL_MEM_FENCE);
    for (int d = lid; d < RADIX; d += RADIX_WG) counts[d * n_tiles + tile] = bins[d];
#endif
}

/* In-place exclusive scan of counts[0..len) by one work-group, SCAN_WG x 4 values per round. */
__kernel __attribute__((reqd_work_group_size(SCAN_WG, 1, 1)))
void radix_scan(uint len, __global uint* counts) {
    __local uint tmp[SCAN_WG];
    int lid = get_local_id(0);
    uint carry = 0;
    for (uint base = 0; base < len; base += 4 * SCAN_WG) {
        uint j = base + 4 * lid;
        uint4 v = (uint4)(0);
        if (j + 3 < len) v = vload4(0, counts + j);
        else {
            if (j < len) v.x = counts[j];
            if (j + 1 < len) v.y = counts[j + 1];
            if (j + 2 < len) v.z = counts[j + 2];
        }
        uint total;
        uint pre = carry + wg_exclusive_scan(v.x + v.y + v.z + v.w, tmp, SCAN_WG, &total);
        uint4 o = (uint4)(pre, pre + v.x, pre + v.x + v.y, pre + v.x + v.y + v.z);
        if (j + 3 < len) vstore4(o, 0, counts + j);
        else {
            if (j < len) counts[j] = o.x;
            if (j + 1 < len) counts[j + 1] = o.y;
            if (j + 2 < len) counts[j + 2] = o.z;
        }
        carry += total;
    }
}

/* Stable split of the tile in lk/lv by the 4 bits at `shift`: each thread ranks its RADIX_ITEMS
   consecutive keys with packed counts, a local scan orders (digit, thread), and the tile is
   rewritten in place in digit order. */
inline void tile_split4(__local uint* lk, __local uint* lv, __local uint* hist, __local uint* tmp,
                        uint shift) {
    int lid = get_local_id(0);
    uint mk[RADIX_ITEMS], mv[RADIX_ITEMS];
    ulong packed = 0;
    for (int k = 0; k < RADIX_ITEMS; ++k) {
        mk[k] = lk[lid * RADIX_ITEMS + k];
        mv[k] = lv[lid * RADIX_ITEMS + k];
        packed += 1ul << (4 * ((mk[k] >> shift) & (SPLIT - 1)));
    }
    for (int d = 0; d < SPLIT; ++d) hist[d * RADIX_WG + lid] = packed_count(packed, d);
    barrier(CLK_LOCAL_MEM_FENCE);
    /* exclusive scan of hist in digit-major order: thread t owns SPLIT consecutive entries */
    uint run[SPLIT];
    uint s = 0;
    for (int q = 0; q < SPLIT; ++q) {
        run[q] = s;
        s += hist[lid * SPLIT + q];
    }
    uint total;
    uint pre = wg_exclusive_scan(s, tmp, RADIX_WG, &total);
    for (int q = 0; q < SPLIT; ++q) hist[lid * SPLIT + q] = pre + run[q];
    barrier(CLK_LOCAL_MEM_FENCE);
    ulong seen = 0;
    for (int k = 0; k < RADIX_ITEMS; ++k) {
        uint d = (mk[k] >> shift) & (SPLIT - 1);
        uint pos = hist[d * RADIX_WG + lid] + packed_count(seen, d);
        seen += 1ul << (4 * d);
        lk[pos] = mk[k];
        lv[pos] = mv[k];
    }
    barrier(CLK_LOCAL_MEM_FENCE);
}

__kernel __attribute__((reqd_work_group_size(RADIX_WG, 1, 1)))
void radix_scatter(uint n, uint shift, __global const uint* restrict keys_in,
                   __global const uint* restrict vals_in, __global uint* restrict keys_out,
                   __global uint* restrict vals_out, __global const uint* restrict offsets,
                   uint n_tiles, uint fused) {
    __local uint lk[RADIX_TILE];
    __local uint lv[RADIX_TILE];
    __local uint hist[SPLIT * RADIX_WG];
    __local uint tmp[RADIX_WG];
    __local uint dstart[RADIX], gofs[RADIX];
    int lid = get_local_id(0);
    uint tile = get_group_id(0);
    uint base = tile * RADIX_TILE;
    uint valid = min((uint)RADIX_TILE, n - base);
    /* coalesced load; padding keys sort last (largest digit, highest position) */
    for (int k = 0; k < RADIX_ITEMS; ++k) {
        uint j = k * RADIX_WG + lid;
        lk[j] = j < valid ? keys_in[base + j] : 0xffffffffu;
        lv[j] = j < valid ? vals_in[base + j] : 0u;
    }
    if (!fused) {
        for (int d = lid; d < RADIX; d += RADIX_WG) gofs[d] = offsets[d * n_tiles + tile];
    } else {
        /* offsets holds raw counts: the output position of digit d in this tile is the count of
           all smaller digits plus the count of d in earlier tiles. RADIX_WG / RADIX lanes per
           digit sum strided tiles, then a work-group scan over the digit totals. */
        const uint lanes = RADIX_WG / RADIX;
        uint d = lid / lanes, lane = lid % lanes;
        uint before = 0, total = 0;
        for (uint t = lane; t < n_tiles; t += lanes) {
            uint c = offsets[d * n_tiles + t];
            total += c;
            before += t < tile ? c : 0u;
        }
        if (lanes > 1) {
            hist[lid] = before;
            hist[RADIX_WG + lid] = total;
            barrier(CLK_LOCAL_MEM_FENCE);
            before = total = 0;
            if (lid < RADIX)
                for (uint k = 0; k < lanes; ++k) {
                    before += hist[lid * lanes + k];
                    total += hist[RADIX_WG + lid * lanes + k];
                }
            barrier(CLK_LOCAL_MEM_FENCE);
        }
        uint all;
        uint smaller = wg_exclusive_scan(lid < RADIX ? total : 0u, tmp, RADIX_WG, &all);
        if (lid < RADIX) gofs[lid] = smaller + before;
    }
    barrier(CLK_LOCAL_MEM_FENCE);
    for (uint sub = 0; sub < RADIX_BITS; sub += SPLIT_BITS)
        tile_split4(lk, lv, hist, tmp, shift + sub);
    /* where each digit's run starts in the sorted tile */
    for (int k = 0; k < RADIX_ITEMS; ++k) {
        uint j = k * RADIX_WG + lid;
        uint d = digit_of(lk[j], shift);
        if (j == 0 || digit_of(lk[j - 1], shift) != d) dstart[d] = j;
    }
    barrier(CLK_LOCAL_MEM_FENCE);
    for (int k = 0; k < RADIX_ITEMS; ++k) {
        uint j = k * RADIX_WG + lid;
        if (j < valid) {
            uint key = lk[j];
            uint d = digit_of(key, shift);
            uint dst = gofs[d] + j - dstart[d];
            keys_out[dst] = key;
            vals_out[dst] = lv[j];
        }
    }
}
