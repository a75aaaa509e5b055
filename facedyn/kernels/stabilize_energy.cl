// Mode-pursuit energy and gradient (facedyn.stabilize.opencl; NumPy twin:
// facedyn.stabilize.energy.NumpyEnergy). One work-item = one frame x one block of
// vertices, walked 8 at a time with float8 vectors; no barriers, partial sums per
// work-item are added up in float64 on the host.
//
// points: (F, 3, NP) float, NP = vertices padded to the block size (padding: weight 0),
//         already moved by the evaluator's base transforms (see energy.py: rebasing)
// rt:     (F, 12) row-major dR - I (9 values) then dt (3): S_f = X_f + (dR_f - I) X_f + dt_f
// Penalty: c = clamp(x, -w, w), h = clamp(c, -w/2, w/2), e = c - h:
//          psi w^2 = 2 c^2 - 4 e^2, d psi / dx = 4 (h - e) / w^2.

inline float8 fade8(float8 x, float w, float8 *g)
{
    float8 c = clamp(x, -w, w);
    float8 h = clamp(c, -0.5f * w, 0.5f * w);
    float8 e = c - h;
    *g = h - e;
    return 2.0f * c * c - 4.0f * e * e;
}

inline float sum8(float8 v)
{
    float4 s = v.lo + v.hi;
    return s.x + s.y + s.z + s.w;
}

// Stabilized points S_f = X_f + (dR_f - I) X_f + dt_f into stabilized (F, 3, NP).
__kernel void stabilize_points(
    __global const float *points,
    __global const float *rt,
    const int np,
    const int block,
    __global float *stabilized)
{
    const int b = get_global_id(0);
    const int f = get_global_id(1);
    __global const float *r = rt + f * 12;
    const float r0 = r[0], r1 = r[1], r2 = r[2], r3 = r[3], r4 = r[4], r5 = r[5];
    const float r6 = r[6], r7 = r[7], r8 = r[8], t0 = r[9], t1 = r[10], t2 = r[11];
    for (int n = b * block; n < (b + 1) * block; n += 8) {
        const size_t i = (size_t)f * 3 * np + n;
        const float8 x = vload8(0, points + i), y = vload8(0, points + i + np), z = vload8(0, points + i + 2 * np);
        vstore8(x + (r0 * x + r1 * y + r2 * z + t0), 0, stabilized + i);
        vstore8(y + (r3 * x + r4 * y + r5 * z + t1), 0, stabilized + i + np);
        vstore8(z + (r6 * x + r7 * y + r8 * z + t2), 0, stabilized + i + 2 * np);
    }
}

// Velocities by the per-frame stencil (start[f], stencil[f, 0..width)), their energy
// (times wv^2, per work-item) and dE/dv (weighted, scaled) into grad_vel.
__kernel void stabilize_velocity(
    __global const float *stabilized,
    __global const int *start,
    __global const float *stencil,
    __global const float *weights,
    const int np,
    const int width,
    const int block,
    const float wv,
    const float gscale,
    __global float *grad_vel,
    __global float *energy)
{
    const int b = get_global_id(0);
    const int f = get_global_id(1);
    const int nblocks = get_global_size(0);
    __global const float *base = stabilized + (size_t)start[f] * 3 * np;
    float c[7];
    for (int k = 0; k < 7; ++k)
        c[k] = stencil[f * 7 + k];
    float8 acc = (float8)(0.0f);
    for (int n = b * block; n < (b + 1) * block; n += 8) {
        float8 vx = (float8)(0.0f), vy = (float8)(0.0f), vz = (float8)(0.0f);
        for (int k = 0; k < width; ++k) {
            __global const float *p = base + (size_t)k * 3 * np + n;
            vx += c[k] * vload8(0, p);
            vy += c[k] * vload8(0, p + np);
            vz += c[k] * vload8(0, p + 2 * np);
        }
        const float8 w = vload8(0, weights + n);
        float8 gx, gy, gz;
        acc += w * (fade8(vx, wv, &gx) + fade8(vy, wv, &gy) + fade8(vz, wv, &gz));
        const float8 s = gscale * w;
        __global float *out = grad_vel + (size_t)f * 3 * np + n;
        vstore8(s * gx, 0, out);
        vstore8(s * gy, 0, out + np);
        vstore8(s * gz, 0, out + 2 * np);
    }
    energy[f * nblocks + b] = sum8(acc);
}

// Position energy (times wp^2) and dE/dS = position term + D^T grad_vel, reduced with
// [X; 1] to 12 numbers per frame and block: out[f, b, 0..11] = dE/d[dR | dt] (row-major
// 3 x 4), out[f, b, 12] = position energy.
__kernel void stabilize_gradient(
    __global const float *points,
    __global const float *rt,
    __global const float *rest,
    __global const float *weights,
    __global const int *dt_ptr,
    __global const int *dt_idx,
    __global const float *dt_val,
    __global const float *grad_vel,
    const int np,
    const int block,
    const int with_velocity,
    const float wp,
    const float gscale,
    __global float *out)
{
    const int b = get_global_id(0);
    const int f = get_global_id(1);
    const int nblocks = get_global_size(0);
    __global const float *r = rt + f * 12;
    const int j0 = dt_ptr[f], j1 = with_velocity ? dt_ptr[f + 1] : j0;
    float8 a0 = (float8)(0.0f), a1 = a0, a2 = a0, a3 = a0, a4 = a0, a5 = a0;
    float8 a6 = a0, a7 = a0, a8 = a0, a9 = a0, a10 = a0, a11 = a0, epos = a0;
    for (int n = b * block; n < (b + 1) * block; n += 8) {
        __global const float *p = points + (size_t)f * 3 * np + n;
        const float8 x = vload8(0, p), y = vload8(0, p + np), z = vload8(0, p + 2 * np);
        const float8 dx = (x - vload8(0, rest + n)) + (r[0] * x + r[1] * y + r[2] * z + r[9]);
        const float8 dy = (y - vload8(0, rest + np + n)) + (r[3] * x + r[4] * y + r[5] * z + r[10]);
        const float8 dz = (z - vload8(0, rest + 2 * np + n)) + (r[6] * x + r[7] * y + r[8] * z + r[11]);
        const float8 w = vload8(0, weights + n);
        float8 gx, gy, gz;
        epos += w * (fade8(dx, wp, &gx) + fade8(dy, wp, &gy) + fade8(dz, wp, &gz));
        const float8 s = gscale * w;
        gx *= s;
        gy *= s;
        gz *= s;
        for (int j = j0; j < j1; ++j) {
            const float c = dt_val[j];
            __global const float *q = grad_vel + (size_t)dt_idx[j] * 3 * np + n;
            gx += c * vload8(0, q);
            gy += c * vload8(0, q + np);
            gz += c * vload8(0, q + 2 * np);
        }
        a0 += gx * x; a1 += gx * y; a2 += gx * z; a3 += gx;
        a4 += gy * x; a5 += gy * y; a6 += gy * z; a7 += gy;
        a8 += gz * x; a9 += gz * y; a10 += gz * z; a11 += gz;
    }
    __global float *o = out + (size_t)(f * nblocks + b) * 13;
    o[0] = sum8(a0); o[1] = sum8(a1); o[2] = sum8(a2); o[3] = sum8(a3);
    o[4] = sum8(a4); o[5] = sum8(a5); o[6] = sum8(a6); o[7] = sum8(a7);
    o[8] = sum8(a8); o[9] = sum8(a9); o[10] = sum8(a10); o[11] = sum8(a11);
    o[12] = sum8(epos);
}
