// RGBA8 image -> planar yuv420p (BT.601 limited range, what ffmpeg's swscale uses by default for
// rgb24 -> yuv420p), for the video encoder: Y plane (h x w), then U and V planes (ch x cw with
// cw = (w+1)/2, ch = (h+1)/2). Fixed-point integers, so every device gives the same bytes as
// kernels/video_yuv.py's NumPy twin. One work item per 2x2 block: its (up to) four Y values and
// one U, V from the block's RGB sum; at an odd width/height the last column/row is repeated.
//
//   Y  = 16  + ( 65.481 R + 128.553 G +  24.966 B) / 255
//   Cb = 128 + (-37.797 R -  74.203 G + 112.000 B) / 255     (R, G, B in 0..255, Cb/Cr from
//   Cr = 128 + (112.000 R -  93.786 G -  18.214 B) / 255      the mean of the 2x2 block)
// each rounded half up in 16-bit fixed point: coefficients YR.. below are round(c / 255 * 2^16);
// chroma is shifted by 2 more bits (the block sum is 4 pixels). The fixed point is within 0.006
// of the exact value, so a code differs from the float64 rounding only next to a .5 boundary.

#define YR 16829
#define YG 33039
#define YB 6416
#define UR (-9714)
#define UG (-19070)
#define UB 28784
#define VR 28784
#define VG (-24103)
#define VB (-4681)

inline uchar luma(uchar4 p) {
    return (uchar)((YR * (int)p.x + YG * (int)p.y + YB * (int)p.z + (16 << 16) + 32768) >> 16);
}

__kernel void rgba_to_yuv420p(__global const uchar4 *rgba, __global uchar *yuv,
                              const int width, const int height) {
    const int cx = get_global_id(0), cy = get_global_id(1);
    const int cw = (width + 1) / 2, ch = (height + 1) / 2;
    if (cx >= cw || cy >= ch) return;
    const int x0 = 2 * cx, y0 = 2 * cy;
    const int x1 = min(x0 + 1, width - 1), y1 = min(y0 + 1, height - 1);
    const uchar4 a = rgba[y0 * width + x0], b = rgba[y0 * width + x1];
    const uchar4 c = rgba[y1 * width + x0], d = rgba[y1 * width + x1];
    yuv[y0 * width + x0] = luma(a);
    if (x1 > x0) yuv[y0 * width + x1] = luma(b);
    if (y1 > y0) {
        yuv[y1 * width + x0] = luma(c);
        if (x1 > x0) yuv[y1 * width + x1] = luma(d);
    }
    const int r = (int)a.x + b.x + c.x + d.x, g = (int)a.y + b.y + c.y + d.y;
    const int bl = (int)a.z + b.z + c.z + d.z;
    const int u = (UR * r + UG * g + UB * bl + (128 << 18) + (1 << 17)) >> 18;
    const int v = (VR * r + VG * g + VB * bl + (128 << 18) + (1 << 17)) >> 18;
    const int plane = width * height, k = cy * cw + cx;
    yuv[plane + k] = (uchar)u;
    yuv[plane + cw * ch + k] = (uchar)v;
}
