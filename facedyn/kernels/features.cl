// Windowed velocity features of papers/000 (eqs. 1-4) for all frames and items at once.
//
// One work-item per (frame t, item). Items 0..S-1 are skin samples and write X_i(t), items
// S..S+L-1 are skull landmarks and write their block of B(t). Entry j of a window is the
// velocity at frame k = t - W + j over the frame pair (k-1, k), expressed in the skull frame
// of k; it is zero where k < 1 or k > F-1 (the clamped ends, see facedyn.dynamics.features).
//
// `frames` holds 36 floats per frame k (entry 0 unused), prepared in float64 on the host:
//   [0..8]   R_k^T                  (row-major)
//   [9..17]  R_k^T - R_{k-1}^T
//   [18..20] t_k - t_{k-1}
//   [21..23] t_{k-1}
//   [24..32] I - R_k^T R_{k-1}       (the rotation part of I - T(k)^-1 T(k-1))
//   [33..35] R_k^T (t_k - t_{k-1})    (its translation part)
// The skin velocity T(k)^-1 x(k) - T(k-1)^-1 x(k-1) is evaluated as
//   R_k^T ((x(k) - x(k-1)) - (t_k - t_{k-1})) + (R_k^T - R_{k-1}^T)(x(k-1) - t_{k-1}),
// the same value rearranged so that float32 never subtracts two large world positions
// after rotating them: every term is already small where it is formed.

#define STRIDE 36

inline float3 mat3_mul(__global const float *m, const float3 v)
{
    return (float3)(m[0] * v.x + m[1] * v.y + m[2] * v.z,
                    m[3] * v.x + m[4] * v.y + m[5] * v.z,
                    m[6] * v.x + m[7] * v.y + m[8] * v.z);
}

__kernel void windowed_velocities(__global const float *points,    // (F, S, 3)
                                  __global const float *frames,    // (F, STRIDE)
                                  __global const float *landmarks, // (L, 3) skull space
                                  const int F, const int S, const int L, const int W,
                                  const float inv_dt,
                                  __global float *skin,            // (F, S, (2W+1)*3)
                                  __global float *skull)           // (F, L*(2W+1)*3)
{
    const size_t gid = get_global_id(0);
    const int items = S + L;
    if (gid >= (size_t)F * items)
        return;
    const int t = (int)(gid / items);
    const int item = (int)(gid % items);
    const int width = 2 * W + 1;

    if (item < S) {
        __global float *out = skin + ((size_t)t * S + item) * (size_t)(width * 3);
        for (int j = 0; j < width; ++j) {
            const int k = t - W + j;
            float3 v = (float3)(0.0f);
            if (k >= 1 && k < F) {
                __global const float *m = frames + (size_t)k * STRIDE;
                const float3 x1 = vload3((size_t)k * S + item, points);
                const float3 x0 = vload3((size_t)(k - 1) * S + item, points);
                const float3 dt = (float3)(m[18], m[19], m[20]);
                const float3 t0 = (float3)(m[21], m[22], m[23]);
                v = (mat3_mul(m, (x1 - x0) - dt) + mat3_mul(m + 9, x0 - t0)) * inv_dt;
            }
            vstore3(v, j, out);
        }
    } else {
        const int l = item - S;
        const float3 b = vload3(l, landmarks);
        __global float *out = skull + (size_t)t * (size_t)(L * width * 3) + (size_t)(l * width * 3);
        for (int j = 0; j < width; ++j) {
            const int k = t - W + j;
            float3 v = (float3)(0.0f);
            if (k >= 1 && k < F) {
                __global const float *m = frames + (size_t)k * STRIDE;
                v = (mat3_mul(m + 24, b) + (float3)(m[33], m[34], m[35])) * inv_dt;
            }
            vstore3(v, j, out);
        }
    }
}
