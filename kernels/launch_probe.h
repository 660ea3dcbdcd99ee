/* The by-value struct of launch_probe.cl, the kernel that tests kernels.launch with every kind
   of argument. Mirrored by PROBE_DTYPE in tests/kernels/test_launch.py (layout tested there). */
#ifndef LBWATER_LAUNCH_PROBE_H
#define LBWATER_LAUNCH_PROBE_H

/* 16 bytes. */
typedef struct {
    float scale;
    float bias;
    uint count;
    int sign;
} ProbeParams;

#endif
