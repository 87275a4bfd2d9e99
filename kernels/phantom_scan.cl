/* Ultrasound phantom with physics in physical units (`softshell phantom
 * --physics NAME`): the geometry and truth of phantom.cl (included, with
 * -D POSE for a rigid pose of the scene), imaged along the beams of a linear
 * array or a fan.
 *
 * The image is formed where a scanner forms it, on a beam grid (u, v, w):
 * lateral, elevational and depth sample along the beams. For a linear array
 * it is the voxel grid itself (beams along +z); for a fan its cells lie on
 * rays from an apex above the volume (u: angle in x, v: y for a curvilinear
 * probe swept along y, or the angle in y for a volume probe; w: radius), so
 * attenuation, shadows and the PSF follow the rays, and a PSF of constant
 * width in cells widens in mm with depth. Then the B-mode grey levels are scan
 * converted (trilinear) onto the voxel grid; voxels outside the scanned
 * sector are 0.
 *
 * Kernels (host: host/phantom_scan.cpp; model: docs/phantom.md):
 *   phantom_geometry, phantom_redistance_x/y/z  (phantom.cl, -D POSE)
 *   phantom_scan_finish   final signed distance per voxel
 *   phantom_scan_echo     per beam cell: scatterers (from sparse points to
 *                         fully developed speckle), boundary echoes, the
 *                         layered near field and its reverberations, and
 *                         the cell's two-way loss
 *   phantom_scan_attenuate  along w: depth attenuation, shadows
 *   phantom_scan_psf_x/y/z  separable Gaussian PSF, per-depth widths
 *   phantom_scan_bmode    time-gain compensation, noise, envelope, log
 *   phantom_scan_convert  beam grid -> voxels (uint8), the label volume and
 *                         the shadow volume
 *
 * Parameters: one float array, indices in phantom_scan.h.
 */
#define PHANTOM_SCAN 1
#include "phantom.cl"
#include "phantom_scan.h"

#ifndef POSE
#error "phantom_scan.cl needs -D POSE"
#endif

INLINE VF cos_poly(VF v) { return sin_poly(v + 1.57079633f); }

/* atan(t) for |t| <= 1; |error| < 2e-5 rad. */
INLINE VF atan_poly(VF t) {
  const VF t2 = t * t;
  return t * (0.99997726f +
              t2 * (-0.33262347f + t2 * (0.19354346f + t2 * (-0.11643287f + t2 * (0.05265332f - 0.01172120f * t2)))));
}

/* Gathers of one float per lane. */
INLINE VF gather(__global const float* restrict p, VI idx) {
#if LANES == 8
  int ii[8];
  vstore8(idx, 0, ii);
  float t[8];
  for (int k = 0; k < 8; ++k) t[k] = p[ii[k]];
  return vload8(0, t);
#else
  return p[idx];
#endif
}

INLINE float16 pose_of(__global const float* restrict P) {
  return (float16)(P[PS_POSE + 0], P[PS_POSE + 1], P[PS_POSE + 2], P[PS_POSE + 3], P[PS_POSE + 4], P[PS_POSE + 5],
                   P[PS_POSE + 6], P[PS_POSE + 7], P[PS_POSE + 8], P[PS_POSE + 9], P[PS_POSE + 10], P[PS_POSE + 11],
                   0.0f, 0.0f, 0.0f, 0.0f);
}

/* exp(-u^2 / 2) */
INLINE VF gauss(VF u) { return exp2_poly(-0.72134752f * u * u); }

/* ---- beam geometry -------------------------------------------------------- */

/* A beam cell: its centre (world mm), beam direction, depth below the probe
 * surface d, lateral coordinates along the probe surface (mm) and volume. */
typedef struct {
  VF x, y, z, bx, by, bz, d, lat1, lat2, vol;
} Cell;

INLINE Cell beam_cell(__global const float* restrict P, const GridDesc bg, VF u, float v, float w) {
  Cell c;
  const int kind = (int)P[PS_KIND];
  const float h = P[PS_H], R = P[PS_R], dr = P[PS_DR];
  if (kind == 0) {
    c.x = (u + 0.5f - 0.5f * (float)bg.nx) * h;
    c.y = (VF)((v + 0.5f - 0.5f * (float)bg.ny) * h);
    c.z = (VF)((w + 0.5f) * h);
    c.bx = (VF)(0.0f), c.by = (VF)(0.0f), c.bz = (VF)(1.0f);
    c.d = c.z;
    c.lat1 = c.x, c.lat2 = c.y;
    c.vol = (VF)(h * h * h);
    return c;
  }
  const float r = R + (w + 0.5f) * dr;
  const VF ax = (u + 0.5f - 0.5f * (float)bg.nx) * P[PS_DTH_X];
  const VF sx = sin_poly(ax), cx = cos_poly(ax);
  c.d = (VF)(r - R);
  c.lat1 = R * ax;
  if (kind == 1) {
    c.bx = sx, c.by = (VF)(0.0f), c.bz = cx;
    c.y = (VF)((v + 0.5f - 0.5f * (float)bg.ny) * h);
    c.lat2 = c.y;
    c.vol = (VF)(r * P[PS_DTH_X] * h * dr);
  } else {
    const VF ay = (VF)((v + 0.5f - 0.5f * (float)bg.ny) * P[PS_DTH_Y]);
    const VF tx = sx / cx, ty = sin_poly(ay) / cos_poly(ay);
    const VF q = 1.0f / sqrt(1.0f + tx * tx + ty * ty);
    c.bx = tx * q, c.by = ty * q, c.bz = q;
    c.y = r * c.by;
    c.lat2 = R * ay;
    c.vol = r * r * dr * P[PS_DTH_X] * P[PS_DTH_Y] * (1.0f + tx * tx) * (1.0f + ty * ty) * q * q * q;
  }
  c.x = r * c.bx;
  c.z = r * c.bz - R;
  return c;
}

/* World point -> beam grid coordinates (cell centres at integers), depth d,
 * lateral coordinates, and whether the point lies in the scanned region. */
typedef struct {
  VF u, v, w, d, lat1, lat2;
  VI inside;
} BeamPos;

INLINE BeamPos beam_pos(__global const float* restrict P, const GridDesc bg, VF x, VF y, VF z) {
  BeamPos b;
  const int kind = (int)P[PS_KIND];
  const float h = P[PS_H], R = P[PS_R], dr = P[PS_DR];
  if (kind == 0) {
    b.u = x * (1.0f / h) + 0.5f * (float)bg.nx - 0.5f;
    b.v = y * (1.0f / h) + 0.5f * (float)bg.ny - 0.5f;
    b.w = z * (1.0f / h) - 0.5f;
    b.d = z, b.lat1 = x, b.lat2 = y;
    b.inside = (z >= 0.0f) & (z <= P[PS_DEPTH]);
    return b;
  }
  const VF zz = z + R; /* > 0: the apex lies above the volume */
  const VF tx = x / zz;
  VI in = (fabs(tx) <= P[PS_TAN_X]) & (zz > 0.0f);
  const VF ax = atan_poly(clampf(tx, -1.0f, 1.0f));
  b.u = ax * (1.0f / P[PS_DTH_X]) + 0.5f * (float)bg.nx - 0.5f;
  b.lat1 = R * ax;
  VF r;
  if (kind == 1) {
    r = len2(x, zz);
    b.v = y * (1.0f / h) + 0.5f * (float)bg.ny - 0.5f;
    b.lat2 = y;
  } else {
    const VF ty = y / zz;
    in &= fabs(ty) <= P[PS_TAN_Y];
    const VF ay = atan_poly(clampf(ty, -1.0f, 1.0f));
    r = len3(x, y, zz);
    b.v = ay * (1.0f / P[PS_DTH_Y]) + 0.5f * (float)bg.ny - 0.5f;
    b.lat2 = R * ay;
  }
  b.d = r - R;
  b.w = b.d * (1.0f / dr) - 0.5f;
  b.inside = in & (b.d >= 0.0f) & (b.d <= P[PS_DEPTH]);
  return b;
}

/* ---- near field ---------------------------------------------------------- */

/* Depth of near-field interface i (0: the skin surface, always 0; 1: skin /
 * fat, 2: fat / muscle, 3: muscle / what lies below), undulating with the
 * lateral position: b_i (1 + wave * (0.6 sin(k1 . lat + phase) + 0.4 sin(k2 . lat + phase'))),
 * so interfaces never cross (docs/phantom.md). */
INLINE VF nf_interface(__global const float* restrict P, VF lat1, VF lat2, int i) {
  const VF a = P[PS_NF_K + 0] * lat1 + P[PS_NF_K + 1] * lat2 + P[PS_NF_PHASE + 2 * i];
  const VF b = P[PS_NF_K + 2] * lat1 + P[PS_NF_K + 3] * lat2 + P[PS_NF_PHASE + 2 * i + 1];
  return P[PS_NF_B + i - 1] * (1.0f + P[PS_NF_WAVE] * (0.6f * sin_poly(a) + 0.4f * sin_poly(b)));
}

/* ---- per-voxel truth ------------------------------------------------------ */

__kernel void phantom_scan_finish(__global float* restrict sdf, __global const uint* restrict seed, const GridDesc g) {
  const int ix0 = get_global_id(0) * LANES, iy = get_global_id(1), iz = get_global_id(2);
  if (!grid_contains(g, ix0, iy, iz)) return;
  const size_t idx = grid_index(g, ix0, iy, iz);
  const int count = g.nx - ix0;
  store_lanes(sdf + idx, final_distance(load_lanes(sdf + idx, count), load_lanes_u(seed + idx, count)), count);
}

/* ---- echo ----------------------------------------------------------------- */

/* Echogenicity texture (object frame, mm), mean ~1. */
INLINE VF scan_texture(VF x, VF y, VF z, VF w_in, uint key, float amp) {
  const float f = 1.0f / 6.0f;
  const VF t = 1.0f + amp * value_noise(x * f, y * f, z * f, key);
#if SHAPE == 1 /* muscle around the bone: fibres along the spine (x) */
  const VF fib = 1.0f + 1.7f * amp * value_noise(x * 0.06f, y * 0.21f, z * 0.48f, key ^ 0x85ebca6bu);
  return fmax(mixf(fib, t, w_in), 0.05f);
#else
  (void)w_in;
  return fmax(t, 0.05f);
#endif
}

__kernel void phantom_scan_echo(__global const float* restrict sdf, __global const float* restrict aux,
                                const GridDesc vg, __global float* restrict re, __global float* restrict im,
                                __global float* restrict loss, const GridDesc bg, __global const float* restrict P,
                                const uint scatter_key, const uint texture_key, const uint point_key) {
  const int u0 = get_global_id(0) * LANES, v = get_global_id(1), w = get_global_id(2);
  if (!grid_contains(bg, u0, v, w)) return;
  const size_t idx = grid_index(bg, u0, v, w);
  const int count = bg.nx - u0;
  const Cell c = beam_cell(P, bg, TO_FLOAT(u0 + LANE_INDEX), (float)v, (float)w);
  const float h = P[PS_H], dr = P[PS_DR];

  /* The truth distance (voxels) and its gradient, trilinear on the voxel grid. */
  const VF fi = clampf(c.x * (1.0f / h) + 0.5f * (float)vg.nx - 0.5f, 0.0f, (float)vg.nx - 1.0f);
  const VF fj = clampf(c.y * (1.0f / h) + 0.5f * (float)vg.ny - 0.5f, 0.0f, (float)vg.ny - 1.0f);
  const VF fk = clampf(c.z * (1.0f / h) - 0.5f, 0.0f, (float)vg.nz - 1.0f);
  const VF i0 = fmin(floor(fi), (float)vg.nx - 2.0f), j0 = fmin(floor(fj), (float)vg.ny - 2.0f),
           k0 = fmin(floor(fk), (float)vg.nz - 2.0f);
  const VF tx = fi - i0, ty = fj - j0, tz = fk - k0;
  const int sy = vg.nx, sz = vg.nx * vg.ny;
  const VI base = TO_INT(i0) + sy * TO_INT(j0) + sz * TO_INT(k0);
  const VF c000 = gather(sdf, base), c100 = gather(sdf, base + 1), c010 = gather(sdf, base + sy),
           c110 = gather(sdf, base + sy + 1), c001 = gather(sdf, base + sz), c101 = gather(sdf, base + sz + 1),
           c011 = gather(sdf, base + sz + sy), c111 = gather(sdf, base + sz + sy + 1);
  const VF x00 = mixf(c000, c100, tx), x10 = mixf(c010, c110, tx), x01 = mixf(c001, c101, tx),
           x11 = mixf(c011, c111, tx);
  const VF s = mixf(mixf(x00, x10, ty), mixf(x01, x11, ty), tz);
  const VF gx = mixf(mixf(c100 - c000, c110 - c010, ty), mixf(c101 - c001, c111 - c011, ty), tz);
  const VF gy = mixf(x10 - x00, x11 - x01, tz);
  const VF gz = mixf(x01, x11, ty) - mixf(x00, x10, ty);
  const VF gl = fmax(len3(gx, gy, gz), 1e-6f);
  const VF cosb = fabs(gx * c.bx + gy * c.by + gz * c.bz) / gl; /* |n . beam| */
  const VF facing = cosb * cosb * cosb;
  const VI nearest = TO_INT(rint(fi)) + sy * TO_INT(rint(fj)) + sz * TO_INT(rint(fk));
  const VF part = rint(gather(aux, nearest) * 0.25f);

  /* The shape's own frame (design units) for its texture and inner bone. */
  const float ds = P[PS_DESIGN];
  VF ox = c.x * ds, oy = c.y * ds, oz = c.z * ds - 50.0f;
  to_object(pose_of(P), &ox, &oy, &oz);
  const VF w_in = clampf(0.5f - s, 0.0f, 1.0f);
  const VF skull = w_in * inner_bone(ox, oy, oz);
  const float mm = 1.0f / ds;
  const VF tex = scan_texture(ox * mm, oy * mm, oz * mm, w_in, texture_key, P[PS_TEXTURE]);

  /* Outside the object: the background, or the near-field layers. */
  VF e_out = (VF)(P[PS_E_BG]), att_out = (VF)(P[PS_ATT_BG]);
  VF spec_nf = (VF)(0.0f), refl_nf = (VF)(0.0f);
  const float spec_w = P[PS_SPEC_W];
  if (P[PS_NF] > 0.5f) {
    const VF b1 = nf_interface(P, c.lat1, c.lat2, 1), b2 = nf_interface(P, c.lat1, c.lat2, 2),
             b3 = nf_interface(P, c.lat1, c.lat2, 3);
    if (ANY(c.d < b3 + 4.0f * spec_w)) {
      const uint k2 = texture_key ^ 0x27d4eb2fu;
      const VF skin = P[PS_NF_E + 0] * (1.0f + 0.3f * value_noise(c.lat1 * 0.7f, c.lat2 * 0.7f, c.d * 2.0f, k2));
      const VF sept = clampf((value_noise(c.lat1 * 0.4f, c.lat2 * 0.4f, c.d * 1.25f, k2 ^ 0x165667b1u) - 0.3f) * 4.0f,
                             0.0f, 1.0f);
      const VF fat = P[PS_NF_E + 1] * (1.0f + 8.0f * sept);
      const VF mus = P[PS_NF_E + 2] *
                     (1.0f + 0.7f * value_noise(c.lat1 * 0.125f, c.lat2 * 0.125f, c.d * 2.0f, k2 ^ 0x9e3779b9u));
      const VI in_skin = c.d < b1, in_fat = c.d < b2, in_band = c.d < b3;
      const VF e_layer = SEL(in_skin, skin, SEL(in_fat, fat, mus));
      const VF a_layer = SEL(in_skin, (VF)(P[PS_NF_ATT + 0]), SEL(in_fat, (VF)(P[PS_NF_ATT + 1]), (VF)(P[PS_NF_ATT + 2])));
      e_out = SEL(in_band, e_layer, e_out);
      att_out = SEL(in_band, a_layer, att_out);
    }
    /* Interfaces (facing the beam): the skin surface and three fascia-like
     * boundaries, each with two reverberations at twice and three times its
     * depth. */
    const float iw = 1.0f / spec_w, rho = P[PS_NF_REVERB];
    VF direct = gauss(c.d * iw);
    VF rev = (VF)(0.0f);
    const VF bs[3] = {b1, b2, b3};
    for (int i = 0; i < 3; ++i) {
      direct += gauss((c.d - bs[i]) * iw);
      rev += rho * gauss((c.d - 2.0f * bs[i]) * iw) + rho * rho * gauss((c.d - 3.0f * bs[i]) * iw);
    }
    spec_nf = P[PS_NF_SPEC] * (direct + rev);
    refl_nf = P[PS_NF_REFL] * direct;
  }

  const VF e_in = by_part(part, P[PS_E_PART], P[PS_E_PART + 1], P[PS_E_PART + 2]) * tex;
  const VF echo = mixf(e_out, e_in, w_in) + P[PS_E_SKULL] * skull;
  const VF s_mm = s * h;
  const VF layer = gauss(s_mm * (1.0f / spec_w));
  /* Coherent amplitude per cell of a reflector of unit strength (see docs):
   * the profile integrates to the same echo whatever the cell size. */
  const VF norm = (0.5f / spec_w) * sqrt(c.vol);
  const VF spec = (by_part(part, P[PS_SPEC_PART], P[PS_SPEC_PART + 1], P[PS_SPEC_PART + 2]) * facing * layer +
                   spec_nf) * norm;

  /* Scatterers: k ~ Poisson(p) points in the cell, p = density x volume; the
   * cell's complex amplitude sqrt(echo k / p) (g1 + i g2) / sqrt 2 has mean
   * power echo for every p: few bright points when p << 1, fully developed
   * speckle when the PSF holds many. */
  VU ha = AS_UINT(u0 + LANE_INDEX), hb = (VU)((uint)v), hc = (VU)((uint)w), hd = (VU)(scatter_key);
  PCG4D(ha, hb, hc, hd);
  VU pa = AS_UINT(u0 + LANE_INDEX), pb = (VU)((uint)v), pc = (VU)((uint)w), pd = (VU)(point_key);
  PCG4D(pa, pb, pc, pd);
  const VF p = P[PS_RHO] * c.vol;
  VF ratio = fmax(1.0f + normal_v(pb, pc) / sqrt(p), 0.0f); /* k / p, normal approximation for p >= 12 */
  const VI small = p < 12.0f;
  if (ANY(small)) {
    const VF uni = (TO_FLOAT(AS_INT(pa >> 8)) + 0.5f) * (1.0f / 16777216.0f);
    VF term = exp2_poly(-1.44269504f * fmin(p, 12.0f)), cdf = term, k = (VF)(0.0f);
    for (int j = 1; j <= 40; ++j) { /* k < 40: P(k >= 40 | p < 12) < 1e-10 */
      const VI more = uni > cdf;
      if (!ANY(more)) break; /* cdf only grows: no lane's k changes any more */
      k = SEL(more, (VF)((float)j), k);
      term = term * p * (1.0f / (float)j);
      cdf += term;
    }
    ratio = SEL(small, k / p, ratio);
  }
  const VF amp = sqrt(echo * ratio) * 0.70710678f;
  store_lanes(re + idx, normal_v(ha, hb) * amp + spec, count);
  store_lanes(im + idx, normal_v(hc, hd) * amp, count);

  /* Two-way losses over the cell: attenuation, and reflection where the
   * path crosses a boundary (the layer integrates to REFL x facing). */
  const VF att = mixf(att_out, by_part(part, P[PS_ATT_PART], P[PS_ATT_PART + 1], P[PS_ATT_PART + 2]), w_in) +
                 P[PS_ATT_SKULL] * skull;
  const float path = dr * 0.39894228f / spec_w; /* per unit of a unit-height profile */
  const VF loss_db = att * dr + (by_part(part, P[PS_REFL_PART], P[PS_REFL_PART + 1], P[PS_REFL_PART + 2]) * facing *
                                 cosb * layer + refl_nf) * path;
  store_lanes(loss + idx, loss_db, count);
}

/* 10^(-db / 20) for db >= 0, as exp2_poly for float8 and float whatever LANES
 * is (the column kernel below is float8 on every device). */
#define ATTEN_FACTOR(T, TI, AS_F, TO_I)                                                             \
  INLINE T atten_factor_##T(T db) {                                                                 \
    const T v = fmax(fmin(db, 700.0f) * -0.16609640f, -126.0f);                                     \
    const T n = floor(v);                                                                           \
    const T f = (v - n) * 0.69314718f;                                                              \
    const T p = 1.0f + f * (1.0f + f * (0.5f + f * (0.16666667f + f * (0.04166667f + f * (0.00833333f + f * 0.00138889f))))); \
    return AS_F((TO_I(n) + 127) << 23) * p;                                                         \
  }
ATTEN_FACTOR(float8, int8, as_float8, convert_int8)
ATTEN_FACTOR(float, int, as_float, convert_int)

/* Eight neighbouring beams per work-item, marching along w (depth): an echo
 * from a cell is weakened by everything between it and the probe, both ways
 * (half of the cell's own loss: its echo comes from its centre), so deep
 * tissue darkens and strong reflectors and attenuators cast shadows along the
 * beams. In place, the cell's loss becomes the two-way loss (dB) accumulated
 * to its centre. */
__kernel void phantom_scan_attenuate(__global float* restrict re, __global float* restrict im,
                                     __global float* restrict loss, const GridDesc g) {
  const int x0 = 8 * get_global_id(0), y = get_global_id(1);
  if (x0 >= g.nx || y >= g.ny) return;
  const size_t stride = (size_t)g.nx * (size_t)g.ny;
  const size_t start = (size_t)x0 + (size_t)g.nx * (size_t)y;
  if (x0 + 8 <= g.nx) {
    float8 acc = (float8)(0.0f);
    size_t i = start;
    for (int z = 0; z < g.nz; ++z, i += stride) {
      const float8 l = vload8(0, loss + i);
      const float8 centre = acc + 0.5f * l;
      const float8 t = atten_factor_float8(centre);
      vstore8(vload8(0, re + i) * t, 0, re + i);
      vstore8(vload8(0, im + i) * t, 0, im + i);
      vstore8(centre, 0, loss + i);
      acc += l;
    }
  } else {
    for (int x = x0; x < g.nx; ++x) {
      float acc = 0.0f;
      size_t i = start + (size_t)(x - x0);
      for (int z = 0; z < g.nz; ++z, i += stride) {
        const float l = loss[i];
        const float centre = acc + 0.5f * l;
        const float t = atten_factor_float(centre);
        re[i] *= t;
        im[i] *= t;
        loss[i] = centre;
        acc += l;
      }
    }
  }
}

/* ---- point-spread function ------------------------------------------------ */
/* Separable Gaussian on the complex field with weights per depth row w
 * (`weights + w * (2 radius + 1)`, unit energy each; the host computes the
 * beam's width at that depth in cells) or the same for all rows (the axial
 * pass). Near the ends of the grid the taps that fall outside are dropped and
 * the rest rescaled to unit energy, so fully developed speckle keeps its mean
 * power up to the edge (repeating the edge sample would brighten it). */
#define SCAN_PSF_PASS(NAME, COORD, EXTENT, STRIDE, ROW)                                          \
  __kernel void NAME(__global const float* restrict in_re, __global const float* restrict in_im,  \
                     __global float* restrict out_re, __global float* restrict out_im,            \
                     __global const float* restrict weights, const int radius, const GridDesc g) { \
    const int x = get_global_id(0), y = get_global_id(1), z = get_global_id(2);                  \
    if (!grid_contains(g, x, y, z)) return;                                                       \
    const size_t idx = grid_index(g, x, y, z);                                                    \
    const int c = COORD, n = EXTENT;                                                              \
    const size_t stride = STRIDE;                                                                 \
    __global const float* restrict wk = weights + (size_t)(ROW) * (size_t)(2 * radius + 1);       \
    float ar = 0.0f, ai = 0.0f;                                                                   \
    if (c >= radius && c + radius < n) {                                                          \
      const size_t base = idx - (size_t)radius * stride;                                          \
      for (int k = 0; k <= 2 * radius; ++k) {                                                     \
        ar = fma(wk[k], in_re[base + (size_t)k * stride], ar);                                    \
        ai = fma(wk[k], in_im[base + (size_t)k * stride], ai);                                    \
      }                                                                                           \
    } else {                                                                                      \
      const int lo = max(-radius, -c), hi = min(radius, n - 1 - c);                               \
      float e = 0.0f;                                                                             \
      for (int k = lo; k <= hi; ++k) {                                                            \
        const float wv = wk[k + radius];                                                          \
        const size_t j = idx + (ptrdiff_t)k * (ptrdiff_t)stride;                                  \
        ar = fma(wv, in_re[j], ar);                                                               \
        ai = fma(wv, in_im[j], ai);                                                               \
        e = fma(wv, wv, e);                                                                       \
      }                                                                                           \
      const float s = rsqrt(fmax(e, 1e-12f));                                                     \
      ar *= s;                                                                                    \
      ai *= s;                                                                                    \
    }                                                                                             \
    out_re[idx] = ar;                                                                             \
    out_im[idx] = ai;                                                                             \
  }

#if LANES == 1
SCAN_PSF_PASS(phantom_scan_psf_x, x, g.nx, 1, z)
#else
/* The u pass with explicit vectors: LANES outputs per work-item, one
 * unaligned vector load per tap away from the ends of the row. */
__kernel void phantom_scan_psf_x(__global const float* restrict in_re, __global const float* restrict in_im,
                                 __global float* restrict out_re, __global float* restrict out_im,
                                 __global const float* restrict weights, const int radius, const GridDesc g) {
  const int ix0 = get_global_id(0) * LANES, y = get_global_id(1), z = get_global_id(2);
  if (!grid_contains(g, ix0, y, z)) return;
  const size_t idx = grid_index(g, ix0, y, z);
  const int count = g.nx - ix0;
  __global const float* restrict wk = weights + (size_t)z * (size_t)(2 * radius + 1);
  VF ar = (VF)(0.0f), ai = (VF)(0.0f);
  if (ix0 >= radius && ix0 + LANES - 1 + radius < g.nx) {
    const size_t base = idx - radius;
    for (int k = 0; k <= 2 * radius; ++k) {
      const float wv = wk[k];
      ar = fma((VF)(wv), VLOAD(in_re + base + k), ar);
      ai = fma((VF)(wv), VLOAD(in_im + base + k), ai);
    }
  } else {
    const size_t row = idx - ix0;
    float tr[LANES], ti[LANES];
    for (int l = 0; l < LANES; ++l) {
      const int c = min(ix0 + l, g.nx - 1); /* lanes past the row's end are not stored */
      const int lo = max(-radius, -c), hi = min(radius, g.nx - 1 - c);
      float sr = 0.0f, si = 0.0f, e = 0.0f;
      for (int k = lo; k <= hi; ++k) {
        const float wv = wk[k + radius];
        sr = fma(wv, in_re[row + (size_t)(c + k)], sr);
        si = fma(wv, in_im[row + (size_t)(c + k)], si);
        e = fma(wv, wv, e);
      }
      const float s = (lo == -radius && hi == radius) ? 1.0f : rsqrt(fmax(e, 1e-12f));
      tr[l] = sr * s;
      ti[l] = si * s;
    }
    ar = VLOAD_PRIVATE(tr);
    ai = VLOAD_PRIVATE(ti);
  }
  store_lanes(out_re + idx, ar, count);
  store_lanes(out_im + idx, ai, count);
}
#endif
SCAN_PSF_PASS(phantom_scan_psf_y, y, g.ny, (size_t)g.nx, z)
SCAN_PSF_PASS(phantom_scan_psf_z, z, g.nz, (size_t)g.nx * (size_t)g.ny, 0)

/* ---- B-mode --------------------------------------------------------------- */
/* Time-gain compensation (amplitude gain per depth row, host table: it undoes
 * the reference tissue's attenuation and adds the drawn mismatch), then
 * electronic noise (complex Gaussian, rms PS_NOISE in tissue units), the
 * envelope and log compression:
 *   grey = 255 (1 + (10 log10 |s|^2 - top) / range), clamped to [0, 255]
 * (kept as float for the scan conversion). */
__kernel void phantom_scan_bmode(__global const float* restrict re, __global const float* restrict im,
                                 __global float* restrict grey, const GridDesc g, __global const float* restrict gain,
                                 __global const float* restrict P, const uint noise_key) {
  const int ix0 = get_global_id(0) * LANES, iy = get_global_id(1), iz = get_global_id(2);
  if (!grid_contains(g, ix0, iy, iz)) return;
  const size_t idx = grid_index(g, ix0, iy, iz);
  const int count = g.nx - ix0;
  VU a = AS_UINT(ix0 + LANE_INDEX), b = (VU)((uint)iy), c = (VU)((uint)iz), d = (VU)(noise_key);
  PCG4D(a, b, c, d);
  const float gn = gain[iz], sn = P[PS_NOISE] * 0.70710678f;
  const VF i_ = load_lanes(re + idx, count) * gn + normal_v(a, b) * sn;
  const VF q_ = load_lanes(im + idx, count) * gn + normal_v(c, d) * sn;
  const VF power = fmax(i_ * i_ + q_ * q_, 1e-30f);
  const VF db = 3.01029996f * log2_poly(power);
  store_lanes(grey + idx, clampf(255.0f * (1.0f + (db - P[PS_TOP_DB]) / P[PS_DR_DB]), 0.0f, 255.0f), count);
}

/* ---- scan conversion and labels ------------------------------------------ */
/* Per voxel: the grey level interpolated (trilinear) from the beam grid at
 * the voxel's position, shifted by the sweep's slice displacement where the
 * sweep is freehand; 0 outside the scanned region. Labels (truth, no
 * displacement): 3 outside the scanned region, 2 the near-field layers,
 * 1 the object (sdf < 0), 0 the rest. And the shadow (below). */
__kernel void phantom_scan_convert(__global const float* restrict grey, __global const float* restrict loss,
                                   const GridDesc bg, __global const float* restrict sdf,
                                   __global uchar* restrict out, __global uchar* restrict labels,
                                   __global float* restrict shadow, const GridDesc vg,
                                   __global const float* restrict P, const uint jitter_key) {
  const int ix0 = get_global_id(0) * LANES, iy = get_global_id(1), iz = get_global_id(2);
  if (!grid_contains(vg, ix0, iy, iz)) return;
  const size_t idx = grid_index(vg, ix0, iy, iz);
  const int count = vg.nx - ix0;
  const float h = P[PS_H];
  const VF x = (TO_FLOAT(ix0 + LANE_INDEX) + 0.5f - 0.5f * (float)vg.nx) * h;
  const float y = ((float)iy + 0.5f - 0.5f * (float)vg.ny) * h, z = ((float)iz + 0.5f) * h;

  /* Freehand sweeps: the slice at y is displaced in its plane (x, z) by up to
   * PS_JITTER mm, smoothly along y (value noise of period 4 mm). */
  const float jit = P[PS_JITTER];
  VF jx = (VF)(0.0f), jz = (VF)(0.0f);
  if (jit > 0.0f) {
    jx = (VF)(jit * value_noise((VF)(y * 0.25f), (VF)(0.5f), (VF)(0.5f), jitter_key));
    jz = (VF)(jit * value_noise((VF)(y * 0.25f), (VF)(7.5f), (VF)(0.5f), jitter_key));
  }
  const BeamPos img = beam_pos(P, bg, x + jx, (VF)(y), (VF)(z) + jz);
  const VF fu = clampf(img.u, 0.0f, (float)bg.nx - 1.0f), fv = clampf(img.v, 0.0f, (float)bg.ny - 1.0f),
           fw = clampf(img.w, 0.0f, (float)bg.nz - 1.0f);
  const VF u0 = fmin(floor(fu), (float)max(bg.nx - 2, 0)), v0 = fmin(floor(fv), (float)max(bg.ny - 2, 0)),
           w0 = fmin(floor(fw), (float)max(bg.nz - 2, 0));
  const VF tu = fu - u0, tv = fv - v0, tw = fw - w0;
  const int sv = bg.nx, sw = bg.nx * bg.ny;
  const VI base = TO_INT(u0) + sv * TO_INT(v0) + sw * TO_INT(w0);
  const VF g00 = mixf(gather(grey, base), gather(grey, base + 1), tu);
  const VF g10 = mixf(gather(grey, base + sv), gather(grey, base + sv + 1), tu);
  const VF g01 = mixf(gather(grey, base + sw), gather(grey, base + sw + 1), tu);
  const VF g11 = mixf(gather(grey, base + sw + sv), gather(grey, base + sw + sv + 1), tu);
  const VF val = mixf(mixf(g00, g10, tv), mixf(g01, g11, tv), tw);
  store_lanes_b(out + idx, TO_UCHAR(SEL(img.inside, clampf(rint(val), 0.0f, 255.0f), (VF)(0.0f))), count);
  /* Shadow: the two-way loss to the voxel beyond what the TGC restores (the
   * reference tissue's attenuation over its depth): > 0 in shadows, < 0 where
   * the beam crossed fluid (enhancement); UNSCANNED_LOSS_DB outside the
   * scanned region (no beam went there, so nothing there can be seen: this is
   * what evaluate's recall_visible reads from the volume; finite, so that
   * every tool reads the file). */
  const VF l00 = mixf(gather(loss, base), gather(loss, base + 1), tu);
  const VF l10 = mixf(gather(loss, base + sv), gather(loss, base + sv + 1), tu);
  const VF l01 = mixf(gather(loss, base + sw), gather(loss, base + sw + 1), tu);
  const VF l11 = mixf(gather(loss, base + sw + sv), gather(loss, base + sw + sv + 1), tu);
  const VF lost = mixf(mixf(l00, l10, tv), mixf(l01, l11, tv), tw) - P[PS_ATT_REF] * img.d;
  store_lanes(shadow + idx, SEL(img.inside, lost, (VF)(UNSCANNED_LOSS_DB)), count);

  const BeamPos truth = beam_pos(P, bg, x, (VF)(y), (VF)(z));
  VI band = (VI)(0);
  if (P[PS_NF] > 0.5f) band = truth.d < nf_interface(P, truth.lat1, truth.lat2, 3);
  const VF sd = load_lanes(sdf + idx, count);
  const VF label = SEL(!img.inside, (VF)(3.0f), SEL(band, (VF)(2.0f), SEL(sd < 0.0f, (VF)(1.0f), (VF)(0.0f))));
  store_lanes_b(labels + idx, TO_UCHAR(label), count);
}
