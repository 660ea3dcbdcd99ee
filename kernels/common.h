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
   the runtime defines LBWATER_NVIDIA for NVIDIA's platform.
   Elsewhere, where the device compiles OpenCL C 2.0, or 3.0 with the acq_rel order and device
   scope features, the runtime builds with -cl-std=CL2.0/CL3.0 (kernels.device.cl_std_option) and
   the fence is the standard's device-scope acquire-release fence. Devices with only OpenCL C 1.2
   (and not NVIDIA's) keep mem_fence: the BVH's bottom-up boxes and the secondary-ray ticket then
   rely on the driver making global stores visible before a later atomic, which OpenCL 1.2 does
   not promise. No such device has been tried; `lbwater devices` prints the fence each device
   gets, and bench/stress_bvh.py is the test to run on one. */
#if defined(LBWATER_NVIDIA)
#define DEVICE_FENCE() asm volatile("membar.gl;" ::: "memory")
#elif defined(__OPENCL_C_VERSION__) && __OPENCL_C_VERSION__ >= 200 \
    && (__OPENCL_C_VERSION__ < 300 \
        || (defined(__opencl_c_atomic_order_acq_rel) && defined(__opencl_c_atomic_scope_device)))
#define DEVICE_FENCE() \
    atomic_work_item_fence(CLK_GLOBAL_MEM_FENCE, memory_order_acq_rel, memory_scope_device)
#define LBWATER_ATOMIC_FENCE 1
#else
#define DEVICE_FENCE() mem_fence(CLK_GLOBAL_MEM_FENCE)
#endif

#endif
