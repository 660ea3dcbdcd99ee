/* Shared constants and helpers for every lbwater kernel. */
#ifndef LBWATER_COMMON_H
#define LBWATER_COMMON_H

/* A queue launched at its maximum size: the device-side count decides who works. */
#define GUARD_COUNT(i, count_ptr) if ((i) >= *(count_ptr)) return

#endif
