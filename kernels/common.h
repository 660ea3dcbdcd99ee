/* Shared constants and helpers for every lbwater kernel. */
#ifndef LBWATER_COMMON_H
#define LBWATER_COMMON_H

/* A queue launched at its maximum size: the device-side count decides who works. */
#define GUARD_COUNT(i, count_ptr) if ((i) >= *(count_ptr)) return

/* Device-scope fence for handing data from one work-group to another through an atomic (a flag
   or a ticket): before the atomic on the writing side, after it on the reading side. OpenCL 1.2's
   mem_fence orders only the calling work-item's own accesses, and on NVIDIA it does not make
   earlier stores visible to other multiprocessors: bench/stress_bvh.py measured corrupted BVH
   boxes at 2M triangles on an H100 with it. There it is PTX membar.gl (CUDA's __threadfence);
   the runtime defines LBWATER_NVIDIA for NVIDIA's platform. */
#if defined(LBWATER_NVIDIA)
#define DEVICE_FENCE() asm volatile("membar.gl;" ::: "memory")
#else
#define DEVICE_FENCE() mem_fence(CLK_GLOBAL_MEM_FENCE)
#endif

#endif
