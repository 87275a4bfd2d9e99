/* The slab Gauss-Seidel sweep (kernels/system.cl, "Slab Gauss-Seidel"),
 * written once for two forms of the stencil's storage and included once per
 * form. The includer defines:
 *   GS_NAME(f)       the name of this form's function f;
 *   GS_COEF_PARAMS   the coefficient parameters, GS_COEF_ARGS their names;
 *   GS_OFFD(k, q)    the off-diagonal coefficient k (1..9) stored at voxel q
 *                    (N: the level's slice stride, in scope);
 *   GS_DIAG(q)       the diagonal of row q.
 * No include guard: it is meant to be included more than once. */

/* x = 1 .. nx - 2 of an interior row (y, z interior). */
__attribute__((always_inline)) inline void GS_NAME(gs_row)(GS_COEF_PARAMS, __global const float* restrict bv, __global float* xv,
                                                  const GridDesc g, const size_t row, const int reverse) {
  const size_t N = STENCIL_SLICE(grid_voxels(g));
  const long sy = g.nx, sz = (long)g.nx * g.ny;
  const int n = g.nx - 2;
  for (int done = 0; done < n; done += GS_ROW_CHUNK) {
    const int m = min(GS_ROW_CHUNK, n - done);
    const size_t p0 = row + (size_t)(reverse ? g.nx - 1 - done - m : 1 + done); /* lowest x of the chunk */
    float r[GS_ROW_CHUNK], l[GS_ROW_CHUNK];
    for (int j = 0; j < m; ++j) {
      const int i = reverse ? m - 1 - j : j;
      const size_t p = p0 + i;
      /* The x-neighbour visited later: still its old value. */
      float acc = reverse ? -GS_OFFD(1, p - 1) * xv[p - 1] : -GS_OFFD(1, p) * xv[p + 1];
#define TERM(K, DX, DY, DZ)                                          \
  if (K > 1) {                                                       \
    const long off = (long)(DX) + (long)(DY) * sy + (long)(DZ) * sz; \
    acc = fma(-GS_OFFD(K, p), xv[p + off], acc);                   \
    acc = fma(-GS_OFFD(K, p - off), xv[p - off], acc);             \
  }
      STENCIL_OFFSETS(TERM)
#undef TERM
      const float inv = 1.0f / GS_DIAG(p);
      r[i] = (bv[p] + acc) * inv;
      l[i] = (reverse ? GS_OFFD(1, p) : GS_OFFD(1, p - 1)) * inv;
    }
    /* The serial part, in blocks of 4: with u_prev the value before the block,
     * u_k = m_k u_prev + d_k (m_0 = -l_0, d_0 = r_0, m_k = -l_k m_(k-1),
     * d_k = r_k - l_k d_(k-1)), so the chain through u_prev is one fma per 4
     * voxels; m and d do not wait for it (the plain recurrence, one dependent
     * fma per voxel, bounded the sweep: 1.15-1.2x slower at 105^3). The
     * same values up to rounding (the host reference is the plain recurrence
     * in float64, checked to 1e-5). */
    if (reverse) {
      float u = xv[p0 + m];
      int i = m - 1;
      for (; i >= 3; i -= 4) {
        const float m0 = -l[i], d0 = r[i];
        const float m1 = -l[i - 1] * m0, d1 = fma(-l[i - 1], d0, r[i - 1]);
        const float m2 = -l[i - 2] * m1, d2 = fma(-l[i - 2], d1, r[i - 2]);
        const float m3 = -l[i - 3] * m2, d3 = fma(-l[i - 3], d2, r[i - 3]);
        xv[p0 + i] = fma(m0, u, d0);
        xv[p0 + i - 1] = fma(m1, u, d1);
        xv[p0 + i - 2] = fma(m2, u, d2);
        u = fma(m3, u, d3);
        xv[p0 + i - 3] = u;
      }
      for (; i >= 0; --i) {
        u = fma(-l[i], u, r[i]);
        xv[p0 + i] = u;
      }
    } else {
      float u = xv[p0 - 1];
      int i = 0;
      for (; i + 3 < m; i += 4) {
        const float m0 = -l[i], d0 = r[i];
        const float m1 = -l[i + 1] * m0, d1 = fma(-l[i + 1], d0, r[i + 1]);
        const float m2 = -l[i + 2] * m1, d2 = fma(-l[i + 2], d1, r[i + 2]);
        const float m3 = -l[i + 3] * m2, d3 = fma(-l[i + 3], d2, r[i + 3]);
        xv[p0 + i] = fma(m0, u, d0);
        xv[p0 + i + 1] = fma(m1, u, d1);
        xv[p0 + i + 2] = fma(m2, u, d2);
        u = fma(m3, u, d3);
        xv[p0 + i + 3] = u;
      }
      for (; i < m; ++i) {
        u = fma(-l[i], u, r[i]);
        xv[p0 + i] = u;
      }
    }
  }
}

/* Any x-row: a fixed row (y or z on the boundary) has identity rows and no
 * couplings; an interior row's two ends are fixed and coupled to nothing. */
__attribute__((always_inline)) inline void GS_NAME(gs_any_row)(GS_COEF_PARAMS, __global const float* restrict bv, __global float* xv,
                                                      const GridDesc g, const int y, const int z, const int reverse) {
  const size_t row = (size_t)g.nx * ((size_t)y + (size_t)g.ny * z);
  if (y == 0 || z == 0 || y == g.ny - 1 || z == g.nz - 1) {
    for (int x = 0; x < g.nx; ++x) xv[row + x] = bv[row + x] / GS_DIAG(row + x);
    return;
  }
  xv[row] = bv[row] / GS_DIAG(row);
  xv[row + g.nx - 1] = bv[row + g.nx - 1] / GS_DIAG(row + g.nx - 1);
  if (reverse)
    GS_NAME(gs_row)(GS_COEF_ARGS, bv, xv, g, row, 1);
  else
    GS_NAME(gs_row)(GS_COEF_ARGS, bv, xv, g, row, 0);
}

__kernel void GS_NAME(relax_gs_slabs)(GS_COEF_PARAMS, __global const float* restrict bv,
                             __global float* xv, const int colour, const int reverse, const int slab,
                             const GridDesc g) {
  const int z0 = (2 * (int)get_global_id(0) + colour) * slab;
  if (z0 >= g.nz) return;
  const int z1 = min(z0 + slab, g.nz);
  if (reverse) {
    for (int z = z1 - 1; z >= z0; --z)
      for (int y = g.ny - 1; y >= 0; --y) GS_NAME(gs_any_row)(GS_COEF_ARGS, bv, xv, g, y, z, 1);
  } else {
    for (int z = z0; z < z1; ++z)
      for (int y = 0; y < g.ny; ++y) GS_NAME(gs_any_row)(GS_COEF_ARGS, bv, xv, g, y, z, 0);
  }
}
