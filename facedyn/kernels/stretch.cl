// Surface stretch of papers/000 (eq. 8) for all frames and samples in one launch.
//
// One work-item per (frame t, sample i). D_u and D_v are each a weighted sum over 6 mesh
// vertices: the minus end's triangle with negated barycentric weights, then the plus end's
// (facedyn.dynamics.stretch.UVNeighbourhoods.signed_weights). The weights sum to zero, so
// D = sum_k w_k (y[v_k] - y[i]): every term is a short vector formed from two nearby
// positions, and float32 never cancels two large sums of world positions.

__kernel void stretch(__global const float *points,   // (F, N, 3)
                      __global const int *samples,    // (S,) sample vertices
                      __global const int *vertices,   // (S, 2, 6)
                      __global const float *weights,  // (S, 2, 6)
                      __global const float *neutral,  // (S, 2) |D_u|, |D_v| of the neutral
                      const int F, const int N, const int S,
                      __global float *out)            // (F, S, 2)
{
    const size_t gid = get_global_id(0);
    if (gid >= (size_t)F * S)
        return;
    const size_t t = gid / S;
    const int i = (int)(gid % S);
    __global const float *frame = points + t * (size_t)N * 3;
    const float3 centre = vload3(samples[i], frame);
    for (int d = 0; d < 2; ++d) {
        const int base = (i * 2 + d) * 6;
        float3 diff = (float3)(0.0f);
        for (int k = 0; k < 6; ++k)
            diff += weights[base + k] * (vload3(vertices[base + k], frame) - centre);
        const float rest = neutral[i * 2 + d];
        out[gid * 2 + d] = (length(diff) - rest) / rest;
    }
}
