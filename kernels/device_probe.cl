/* What the compiler saw when it built a program for this device: one launch of one work-item.
   out[0]: __OPENCL_C_VERSION__ (120, 200, 300), out[1]: 1 when DEVICE_FENCE() is the OpenCL 2.0+
   atomic_work_item_fence, out[2]: 1 when it is NVIDIA's membar.gl. 12 bytes. */
#include "common.h"

__kernel void device_probe(__global int *out)
{
    if (get_global_id(0) != 0) return;
    DEVICE_FENCE();  /* compiles on this device */
#if defined(__OPENCL_C_VERSION__)
    out[0] = __OPENCL_C_VERSION__;
#else
    out[0] = 100;
#endif
#if defined(LBWATER_ATOMIC_FENCE)
    out[1] = 1;
#else
    out[1] = 0;
#endif
#if defined(LBWATER_NVIDIA)
    out[2] = 1;
#else
    out[2] = 0;
#endif
}
