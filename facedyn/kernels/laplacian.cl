// Batched sparse matrix times per-frame 3-vectors: out[f] = L @ U[f] for every frame f.
//
// L is CSR (N x N); U and out are (F, N, 3) float32. One work-item per (frame, row), with
// rows fastest so that neighbouring work-items read neighbouring vertices of one frame.

__kernel void csr_apply_frames(__global const int *indptr,
                               __global const int *indices,
                               __global const float *data,
                               __global const float *u,
                               const int N, const int F,
                               __global float *out)
{
    const size_t gid = get_global_id(0);
    if (gid >= (size_t)N * F)
        return;
    const int row = (int)(gid % N);
    const size_t frame = gid / N;
    __global const float *uf = u + frame * (size_t)N * 3;
    float3 acc = (float3)(0.0f);
    for (int p = indptr[row]; p < indptr[row + 1]; ++p)
        acc += data[p] * vload3(indices[p], uf);
    vstore3(acc, row, out + frame * (size_t)N * 3);
}
