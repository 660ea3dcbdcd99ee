/* Test kernel of kernels.launch (tests/kernels/test_launch.py): a buffer, a by-value struct, a
   vector, a scalar and local memory, so binding by name is checked on each kind. One launch:
     out[i] = (p.sign * (p.scale * i + p.bias) + offset.x, offset.y, p.count, n)  for i < n */
#include "launch_probe.h"

__kernel void launch_probe(__global float4* restrict out, const ProbeParams p,
                           const float4 offset, const uint n, __local float* scratch)
{
    const uint i = get_global_id(0);
    scratch[get_local_id(0)] = (float)i;
    barrier(CLK_LOCAL_MEM_FENCE);
    if (i >= n) return;
    out[i] = (float4)(p.sign * (p.scale * scratch[get_local_id(0)] + p.bias) + offset.x,
                      offset.y, (float)p.count, (float)n);
}
