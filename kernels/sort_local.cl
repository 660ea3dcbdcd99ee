/* Sort of up to SORT_LOCAL_MAX (uint key, uint value) pairs by one work-group in local memory
   (raytrace.sort.LocalSorter): a bitonic network over 64-bit (key << 32 | value) words, so equal
   keys keep their values' order (values are 0..n-1 on input: the result is stable). One launch,
   which beats a multi-pass radix sort for the TLAS and for small meshes. */

#ifndef SORT_LOCAL_WG
#define SORT_LOCAL_WG 256
#endif
#define SORT_LOCAL_MAX 2048

__kernel __attribute__((reqd_work_group_size(SORT_LOCAL_WG, 1, 1)))
void sort_local_pairs(uint n, __global uint* keys, __global uint* vals) {
    __local ulong w[SORT_LOCAL_MAX];
    int lid = get_local_id(0);
    uint p = 1;
    while (p < n) p <<= 1;
    for (uint i = lid; i < p; i += SORT_LOCAL_WG)
        w[i] = i < n ? ((ulong)keys[i] << 32) | vals[i] : 0xfffffffffffffffful;
    barrier(CLK_LOCAL_MEM_FENCE);
    for (uint k = 2; k <= p; k <<= 1) {
        for (uint j = k >> 1; j > 0; j >>= 1) {
            for (uint t = lid; t < p / 2; t += SORT_LOCAL_WG) {
                /* t-th pair (a, a + j) of this stage */
                uint a = 2 * j * (t / j) + (t % j);
                uint b = a + j;
                bool up = (a & k) == 0;
                ulong x = w[a], y = w[b];
                if ((x > y) == up) {
                    w[a] = y;
                    w[b] = x;
                }
            }
            barrier(CLK_LOCAL_MEM_FENCE);
        }
    }
    for (uint i = lid; i < n; i += SORT_LOCAL_WG) {
        keys[i] = (uint)(w[i] >> 32);
        vals[i] = (uint)w[i];
    }
}
