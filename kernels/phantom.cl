/* Ultrasound phantom: geometry (implicit surfaces, signed distance) and a
 * convolution image-formation model in the spirit of Field II, on the device.
 *
 * Coordinates: geometry is designed in "design units", the volume spanning
 * [-50, 50]^3 whatever its size and field of view (so a shape always fills the
 * volume the same way); voxel (i, j, k) has its centre at
 * ((i + 0.5) / n - 0.5) * 100. The transducer lies on the z = 0 face (design
 * z = -50) and every beam runs along +z; axial = z, lateral = x, y.
 *
 * Pipeline (host: host/phantom.cpp; model and parameters: docs/phantom.md):
 *   phantom_geometry   per voxel: local signed distance estimate, normal,
 *                      part, and a surface point ("seed") near it
 *   phantom_redistance_x/y/z  nearest seed within a window, axis by axis
 *   phantom_echo       final signed distance; echogenicity, complex
 *                      scatterer + specular echo, per-voxel transmission
 *   phantom_attenuate  per column of 8 (x, y) beams, marching along +z: depth
 *                      attenuation and shadowing (products of transmissions)
 *   phantom_psf_x/y/z  separable Gaussian PSF on the complex (I, Q) field
 *   phantom_bmode      electronic noise, envelope, log compression to uint8
 *   phantom_implicit   the raw implicit function at given points (for tests)
 *
 * Build options: -D SHAPE=0|1|2 (face, spine, sphere), -D RADIUS_LATERAL=r,
 * -D RADIUS_AXIAL=r (PSF taps on each side, compile-time so loops unroll),
 * -D LANES=1|8 (x voxels per work-item in the lane kernels, see "lanes").
 *
 * Random numbers come from a counter-based hash (pcg4d, Jarzynski & Olano,
 * JCGT 2020) of (x, y, z, key), key = hash(seed, stream) from the host, so
 * every voxel's numbers are fixed by its coordinates alone: no dependence on
 * work-group size, scheduling or device (beyond float rounding).
 *
 * Written for PoCL's CPU vectorisation (docs/architecture.md, docs/phantom.md):
 * most kernels use explicit vectors of LANES voxels (see "lanes"), the y and
 * z PSF passes are scalar per voxel for PoCL's loop vectoriser; every helper
 * is always inlined, per-voxel code is branch-free (selects) except for
 * work-item-wide skips, and log2 / exp2 / sin are short polynomials here
 * rather than library calls, which it cannot widen (the library log2 alone
 * made the B-mode kernel 8x slower).
 */
#include "grid.h"

#ifndef SHAPE
#error "phantom.cl needs -D SHAPE=0|1|2"
#endif
#ifndef RADIUS_LATERAL
#define RADIUS_LATERAL 1
#endif
#ifndef RADIUS_AXIAL
#define RADIUS_AXIAL 1
#endif

#define INLINE inline __attribute__((always_inline))

/* ---- lanes ---------------------------------------------------------------- */
/* The voxel kernels (all but the y and z PSF passes and attenuate) handle LANES
 * neighbouring x voxels per work-item with explicit vector types: PoCL's
 * loop vectoriser gives up on them (LLVM's SLP pass first packs parts of the
 * scalar geometry into short vectors, and a loop holding vector instructions
 * is not widened), so CPUs get LANES = 8 (AVX2 width) and GPUs LANES = 1.
 * Element-wise, both compute the same thing. */
#ifndef LANES
#define LANES 1
#endif
#if LANES == 8
typedef float8 VF;
typedef int8 VI;
typedef uint8 VU;
typedef uchar8 VB;
#define TO_UCHAR(v) convert_uchar8(v)
#define AS_INT(v) as_int8(v)
#define AS_UINT(v) as_uint8(v)
#define AS_FLOAT(v) as_float8(v)
#define TO_INT(v) convert_int8(v)
#define TO_FLOAT(v) convert_float8(v)
#define LANE_INDEX ((VI)(0, 1, 2, 3, 4, 5, 6, 7))
#define VLOAD(p) vload8(0, p)
#define VSTORE(v, p) vstore8(v, 0, p)
#define VLOAD_PRIVATE(p) vload8(0, p)
#define VSTORE_PRIVATE(v, p) vstore8(v, 0, p)
#elif LANES == 1
typedef float VF;
typedef int VI;
typedef uint VU;
typedef uchar VB;
#define TO_UCHAR(v) convert_uchar(v)
#define AS_INT(v) as_int(v)
#define AS_UINT(v) as_uint(v)
#define AS_FLOAT(v) as_float(v)
#define TO_INT(v) convert_int(v)
#define TO_FLOAT(v) convert_float(v)
#define LANE_INDEX 0
#define VLOAD(p) (*(p))
#define VSTORE(v, p) (*(p) = (v))
#define VLOAD_PRIVATE(p) (*(p))
#define VSTORE_PRIVATE(v, p) (*(p) = (v))
#else
#error "LANES must be 1 or 8"
#endif
/* cond ? t : e per lane (comparisons give -1 per vector lane, 1 for scalars;
 * select() takes either). */
#define SEL(cond, t, e) select((e), (t), (cond))
/* Whether any lane's condition holds. */
#if LANES == 1
#define ANY(cond) (cond)
#else
#define ANY(cond) any(cond)
#endif

/* Loads / stores of the first `count` lanes (all when count >= LANES). */
#define LANE_IO(SUFFIX, T, VT)                                                  \
  INLINE VT load_lanes##SUFFIX(__global const T* p, int count) {                \
    if (LANES == 1 || count >= LANES) return VLOAD(p);                          \
    T t[LANES];                                                                 \
    for (int k = 0; k < LANES; ++k) t[k] = k < count ? p[k] : (T)0;             \
    return VLOAD_PRIVATE(t);                                                    \
  }                                                                             \
  INLINE void store_lanes##SUFFIX(__global T* p, VT v, int count) {             \
    if (LANES == 1 || count >= LANES) {                                         \
      VSTORE(v, p);                                                             \
      return;                                                                   \
    }                                                                           \
    T t[LANES];                                                                 \
    VSTORE_PRIVATE(v, t);                                                       \
    for (int k = 0; k < count; ++k) p[k] = t[k];                                \
  }
LANE_IO(, float, VF)
LANE_IO(_u, uint, VU)
LANE_IO(_b, uchar, VB)

/* Lanes i = 0 .. LANES-1 of row[start + i] for start + i in [0, n), else 0
 * (the x redistancing pass near the ends of a row). */
INLINE VU load_lanes_shifted_u(__global const uint* row, int start, int n, int count) {
  uint t[LANES];
  for (int k = 0; k < LANES; ++k) t[k] = (k < count && start + k >= 0 && start + k < n) ? row[start + k] : 0u;
  return VLOAD_PRIVATE(t);
}

/* ---- arithmetic helpers (no library calls: PoCL cannot widen those) ------- */

INLINE VF clampf(VF v, float lo, float hi) { return fmin(fmax(v, lo), hi); }
INLINE VF mixf(VF a, VF b, VF t) { return a + (b - a) * t; }
INLINE VF len3(VF x, VF y, VF z) { return sqrt(x * x + y * y + z * z); }
INLINE VF len2(VF x, VF y) { return sqrt(x * x + y * y); }

/* 2^v for v <= 0 (clamped at -126); relative error < 1e-6. */
INLINE VF exp2_poly(VF v) {
  v = fmax(v, -126.0f);
  const VF n = floor(v);
  const VF f = (v - n) * 0.69314718f; /* e^f, f in [0, ln 2) */
  const VF p =
      1.0f + f * (1.0f + f * (0.5f + f * (0.16666667f + f * (0.04166667f + f * (0.00833333f + f * 0.00138889f)))));
  return AS_FLOAT((TO_INT(n) + 127) << 23) * p;
}

/* sin(v): reduction to [-pi, pi] then [-pi/2, pi/2], odd polynomial; |error| < 1e-5. */
INLINE VF sin_poly(VF v) {
  const VF r = v - 6.28318531f * rint(v * 0.15915494f);
  const VF a = SEL(fabs(r) > 1.57079633f, copysign((VF)(3.14159265f), r) - r, r); /* sin(pi - r) = sin r */
  const VF a2 = a * a;
  return a * (1.0f + a2 * (-0.16666667f + a2 * (0.00833333f + a2 * (-0.00019841f + a2 * 2.7557e-6f))));
}

/* log2(v) for v > 0 normal; |error| < 1e-6. */
INLINE VF log2_poly(VF v) {
  const VI bits = AS_INT(v);
  const VF m0 = AS_FLOAT((bits & 0x007fffff) | 0x3f800000); /* [1, 2) */
  const VI big = m0 > 1.41421356f;
  const VF m = SEL(big, 0.5f * m0, m0);
  const VF e = TO_FLOAT(((bits >> 23) & 255) - 127) + SEL(big, (VF)(1.0f), (VF)(0.0f));
  const VF t = (m - 1.0f) / (m + 1.0f), t2 = t * t;
  const VF s = t * (2.0f + t2 * (0.66666667f + t2 * (0.4f + t2 * (0.28571429f + t2 * 0.22222222f))));
  return e + s * 1.44269504f;
}

/* ---- counter-based RNG --------------------------------------------------- */

/* pcg4d (Jarzynski & Olano 2020) on four variables of any unsigned type. */
#define PCG4D(a, b, c, d)                                   \
  do {                                                      \
    a = a * 1664525u + 1013904223u;                         \
    b = b * 1664525u + 1013904223u;                         \
    c = c * 1664525u + 1013904223u;                         \
    d = d * 1664525u + 1013904223u;                         \
    a += b * d, b += c * a, c += a * b, d += b * c;         \
    a ^= a >> 16, b ^= b >> 16, c ^= c >> 16, d ^= d >> 16; \
    a += b * d, b += c * a, c += a * b, d += b * c;         \
  } while (0)

/* Approximately standard normal from two 32-bit words: Irwin-Hall sum of
 * four 16-bit uniforms, centred and scaled to unit variance (excess kurtosis
 * -0.3; the PSF then sums dozens of them). */
INLINE VF normal_v(VU a, VU b) {
  const VF s = TO_FLOAT(AS_INT(a & 0xffffu)) + TO_FLOAT(AS_INT(a >> 16)) + TO_FLOAT(AS_INT(b & 0xffffu)) +
               TO_FLOAT(AS_INT(b >> 16));
  return (s * (1.0f / 65536.0f) - 2.0f) * 1.73205081f;
}

/* One-lane integer hash for the texture lattice: [-1, 1]. */
INLINE VF lattice(VI i, VI j, VI k, uint key) {
  VU h = AS_UINT(i) * 0x8da6b343u + AS_UINT(j) * 0xd8163841u + AS_UINT(k) * 0xcb1ab31fu + key;
  h ^= h >> 16;
  h *= 0x7feb352du;
  h ^= h >> 15;
  h *= 0x846ca68bu;
  h ^= h >> 16;
  return TO_FLOAT(AS_INT(h >> 8)) * (2.0f / 16777216.0f) - 1.0f;
}

/* Value noise in [-1, 1]: the lattice smoothly (C1) interpolated. */
INLINE VF value_noise(VF x, VF y, VF z, uint key) {
  const VF fx = floor(x), fy = floor(y), fz = floor(z);
  VF tx = x - fx, ty = y - fy, tz = z - fz;
  tx = tx * tx * (3.0f - 2.0f * tx);
  ty = ty * ty * (3.0f - 2.0f * ty);
  tz = tz * tz * (3.0f - 2.0f * tz);
  const VI i = TO_INT(fx), j = TO_INT(fy), k = TO_INT(fz);
  const VF x00 = mixf(lattice(i, j, k, key), lattice(i + 1, j, k, key), tx);
  const VF x10 = mixf(lattice(i, j + 1, k, key), lattice(i + 1, j + 1, k, key), tx);
  const VF x01 = mixf(lattice(i, j, k + 1, key), lattice(i + 1, j, k + 1, key), tx);
  const VF x11 = mixf(lattice(i, j + 1, k + 1, key), lattice(i + 1, j + 1, k + 1, key), tx);
  return mixf(mixf(x00, x10, ty), mixf(x01, x11, ty), tz);
}

/* ---- implicit primitives (design units; p given as x, y, z) --------------- */

INLINE VF sd_sphere(VF x, VF y, VF z, float r) { return len3(x, y, z) - r; }

/* (|p / r| - 1) min(r): 1-Lipschitz, so a lower bound on the distance (as
 * every primitive here is, and smooth unions keep it so), exact along the
 * shortest axis; the local correction makes it a distance near the surface. */
INLINE VF sd_ellipsoid(VF x, VF y, VF z, float rx, float ry, float rz) {
  const VF k0 = len3(x * (1.0f / rx), y * (1.0f / ry), z * (1.0f / rz));
  return (k0 - 1.0f) * fmin(rx, fmin(ry, rz));
}

/* Distance to the segment a-b minus r. */
INLINE VF sd_capsule(VF x, VF y, VF z, float ax, float ay, float az, float bx, float by, float bz, float r) {
  const VF px = x - ax, py = y - ay, pz = z - az;
  const float dx = bx - ax, dy = by - ay, dz = bz - az;
  const VF h = clampf((px * dx + py * dy + pz * dz) * (1.0f / (dx * dx + dy * dy + dz * dz)), 0.0f, 1.0f);
  return len3(px - dx * h, py - dy * h, pz - dz * h) - r;
}

/* Exact: the hull of spheres of radii r1 (at a) and r2 (at b) (Quilez),
 * branch-free. */
INLINE VF sd_round_cone(VF x, VF y, VF z, float ax, float ay, float az, float bx, float by, float bz, float r1,
                        float r2) {
  const float dx = bx - ax, dy = by - ay, dz = bz - az;
  const float l2 = dx * dx + dy * dy + dz * dz;
  const float rr = r1 - r2;
  const float a2 = l2 - rr * rr;
  const float il2 = 1.0f / l2;
  const VF px = x - ax, py = y - ay, pz = z - az;
  const VF yy = px * dx + py * dy + pz * dz;
  const VF zz = yy - l2;
  const VF qx = px * l2 - dx * yy, qy = py * l2 - dy * yy, qz = pz * l2 - dz * yy;
  const VF x2 = qx * qx + qy * qy + qz * qz;
  const VF y2 = yy * yy * l2;
  const VF z2 = zz * zz * l2;
  const VF k = (rr > 0.0f ? 1.0f : -1.0f) * rr * rr * x2;
  const VF cap_b = sqrt(x2 + z2) * il2 - r2;
  const VF cap_a = sqrt(x2 + y2) * il2 - r1;
  const VF side = (sqrt(x2 * a2 * il2) + yy * rr) * il2 - r1;
  const VF sz = sign(zz), sy = sign(yy);
  return SEL(sz * a2 * z2 > k, cap_b, SEL(sy * a2 * y2 < k, cap_a, side));
}

/* Cylinder along x, half-length h, radius r, edges rounded by e. */
INLINE VF sd_round_cylinder_x(VF x, VF y, VF z, float r, float h, float e) {
  const VF dr = len2(y, z) - r + e, dh = fabs(x) - h + e;
  return fmin(fmax(dr, dh), 0.0f) + len2(fmax(dr, 0.0f), fmax(dh, 0.0f)) - e;
}

/* Polynomial (quadratic) smooth minimum with blend width k; C1. */
INLINE VF smin(VF a, VF b, float k) {
  const VF h = fmax(k - fabs(a - b), 0.0f) * (1.0f / k);
  return fmin(a, b) - h * h * (k * 0.25f);
}
INLINE VF smax(VF a, VF b, float k) { return -smin(-a, -b, k); }

/* ---- distance: local correction ------------------------------------------ */

/* Voxels: the local estimate is F corrected within SDF_BAND of the surface,
 * blended into the raw F (a lower bound on the distance) over 2 more voxels.
 * Farther out the redistancing takes over; the raw F stays a lower bound, so
 * it can tell the redistancing passes safely which voxels are far. */
#define SDF_BAND 2.0f
#define SEED_UNIT 32.0f /* seed offsets are stored in 1/32 voxel */

/* What one voxel knows about the surface near it: a signed distance estimate
 * in voxels (sign of f), the z component of the unit normal, and a "seed": a
 * point on the surface as an offset from the voxel centre, packed into 32 bits
 * (bit 31 set; 10-bit signed x, y, z in 1/32 voxel), or 0 when it has none. */
typedef struct {
  VF d, nz;
  VU seed;
} Local;

INLINE VU pack_seed(VI qx, VI qy, VI qz) {
  return (VU)(0x80000000u) | (AS_UINT(qx) & 1023u) | ((AS_UINT(qy) & 1023u) << 10) | ((AS_UINT(qz) & 1023u) << 20);
}

INLINE Local local_min(Local a, Local b) {
  const VI second = b.d < a.d;
  Local m;
  m.d = SEL(second, b.d, a.d);
  m.nz = SEL(second, b.nz, a.nz);
  m.seed = SEL(second, b.seed, a.seed);
  return m;
}

/* Defines NAME(x, y, z, arg, vox): Local for one smooth component F(x, y, z,
 * arg) (design units). Smooth unions and the ellipsoids make F only a bound on
 * the distance; near the surface F / |grad F| (gradient by a tetrahedral
 * central difference of step 0.25 voxel) is exact to first order, and one
 * secant step along the normal corrects for |grad F| varying along it. A voxel
 * within a voxel of the surface whose secant residual is small gets the foot
 * point as its seed (a point on the surface); the redistancing passes then
 * turn seeds into distances. Beyond the band the raw F is used, blended over 2
 * voxels; where the gradient degenerates (|grad F| < 0.3) too. The five extra
 * evaluations run only when some lane of the work-item is within the band. */
#define DEFINE_LOCAL_DISTANCE(NAME, F)                                                          \
  INLINE Local NAME(VF x, VF y, VF z, VI arg, float vox) {                                      \
    Local out;                                                                                  \
    const VF f = F(x, y, z, arg) * (1.0f / vox);                                                \
    out.d = f;                                                                                  \
    out.nz = (VF)(0.0f);                                                                        \
    out.seed = (VU)(0u);                                                                        \
    if (!ANY(fabs(f) < SDF_BAND + 2.0f)) return out;                                            \
    const float e = 0.25f * vox;                                                                \
    const VF f0 = F(x + e, y - e, z - e, arg), f1 = F(x - e, y - e, z + e, arg);                \
    const VF f2 = F(x - e, y + e, z - e, arg), f3 = F(x + e, y + e, z + e, arg);                \
    const float s = 1.0f / (4.0f * e);                                                          \
    const VF gx = (f0 - f1 - f2 + f3) * s, gy = (-f0 - f1 + f2 + f3) * s;                       \
    const VF gz = (-f0 + f1 - f2 + f3) * s;                                                     \
    const VF gl = len3(gx, gy, gz);                                                             \
    const VF ig = 1.0f / fmax(gl, 0.3f);                                                        \
    const VF d = f * ig;                                                                        \
    const VF step = d * ig * vox;                                                               \
    const VF r = F(x - gx * step, y - gy * step, z - gz * step, arg) * (1.0f / vox) * ig;       \
    const VF d2 = d + r;                                                                        \
    const VF t = clampf(fabs(f) - SDF_BAND, 0.0f, 2.0f) * 0.5f;                                 \
    const VI use = (t < 1.0f) & (gl >= 0.3f);                                                   \
    out.nz = SEL(use, gz * ig, (VF)(0.0f));                                                     \
    out.d = SEL(use, copysign(fabs(mixf(d2, f, t)), f), f);                                     \
    /* Seed: the foot point p - d2 n, offset in voxels. */                                      \
    const VF k = -d2 * ig * SEED_UNIT;                                                          \
    const VI ok = use & (fabs(d2) < 1.0f) & (fabs(r) < 0.25f);                                  \
    out.seed = SEL(ok, pack_seed(TO_INT(rint(gx * k)), TO_INT(rint(gy * k)), TO_INT(rint(gz * k))), \
                   (VU)(0u));                                                                   \
    return out;                                                                                 \
  }

/* ---- shapes -------------------------------------------------------------- */
/* Per shape: shape_f(x, y, z, &part), the raw implicit function (design units,
 * negative inside tissue; for tests), and shape_local(x, y, z, vox, &part),
 * the local distance estimate, normal and seed (see Local). part: the component
 * nearest p, 0 soft tissue, 1 uterine wall, 2 bone (floats, to select per lane). */

#if SHAPE == 0 /* face: fetal head facing -z (the transducer), wall behind */

/* Design units; y runs from the crown (-y) to the chin (+y), the face looks
 * toward -z. Profile at x = 0: forehead z -18, nose tip -26, lips -22 and -21,
 * chin -20; the back of the head at z 32, the wall from z ~37 on. */
INLINE VF face_head(VF x, VF y, VF z, VI unused) {
  (void)unused;
  const VF ax = fabs(x); /* mirror-symmetric parts */
  VF d = sd_ellipsoid(x, y + 8.0f, z - 7.0f, 24.0f, 26.0f, 25.0f);                            /* cranium */
  d = smin(d, sd_ellipsoid(x, y - 5.0f, z + 6.0f, 13.0f, 11.0f, 11.0f), 6.0f);                 /* mid-face */
  d = smin(d, sd_ellipsoid(x, y - 15.0f, z + 3.0f, 14.0f, 12.0f, 12.0f), 6.0f);                /* jaw */
  d = smin(d, sd_sphere(ax - 10.0f, y - 5.0f, z + 9.0f, 7.0f), 5.0f);                          /* cheeks */
  d = smin(d, sd_capsule(ax, y, z, 0.0f, -9.0f, -17.5f, 10.0f, -8.0f, -15.0f, 3.0f), 4.0f);    /* brow ridge */
  d = smax(d, -sd_sphere(ax - 8.5f, y + 2.5f, z + 19.5f, 4.8f), 3.0f);                         /* eye sockets */
  d = smin(d, sd_ellipsoid(ax - 8.5f, y + 2.5f, z + 15.5f, 3.8f, 2.8f, 2.4f), 1.5f);           /* eyelids */
  d = smin(d, sd_round_cone(x, y, z, 0.0f, -5.0f, -17.0f, 0.0f, 4.0f, -23.0f, 1.8f, 3.2f), 2.5f); /* nose */
  d = smin(d, sd_sphere(ax - 3.0f, y - 5.0f, z + 20.5f, 2.4f), 1.5f);                          /* alae */
  d = smin(d, sd_capsule(x, y, z, 0.0f, 4.5f, -19.0f, 0.0f, 9.5f, -18.5f, 2.2f), 2.0f);        /* philtrum */
  d = smin(d, sd_ellipsoid(x, y - 10.5f, z + 19.0f, 5.0f, 2.5f, 3.0f), 3.0f);                  /* upper lip */
  d = smin(d, sd_ellipsoid(x, y - 15.8f, z + 18.2f, 4.4f, 2.3f, 2.8f), 3.0f);                  /* lower lip */
  d = smax(d, -sd_ellipsoid(x, y - 13.2f, z + 20.5f, 4.6f, 0.5f, 3.0f), 1.0f);                 /* mouth */
  d = smin(d, sd_ellipsoid(x, y - 23.0f, z + 14.5f, 8.0f, 4.5f, 5.5f), 4.0f);                  /* chin */
  d = smin(d, sd_ellipsoid(ax - 23.5f, y - 1.0f, z - 8.0f, 2.5f, 6.5f, 4.5f), 2.0f);           /* ears */
#ifdef POSE /* rotated, the body's far end could enter a corner: the same line, longer */
  d = smin(d, sd_capsule(x, y, z, 0.0f, 24.0f, 10.0f, 0.0f, 140.0f, 20.0869565f, 11.5f), 8.0f); /* neck, body */
#else
  d = smin(d, sd_capsule(x, y, z, 0.0f, 24.0f, 10.0f, 0.0f, 70.0f, 14.0f, 11.5f), 8.0f);      /* neck, body */
#endif
  return d;
}
DEFINE_LOCAL_DISTANCE(face_head_local, face_head)

/* Placenta / uterine wall: everything deeper than a gently wavy sheet
 * z = z0(x, y); returns z0 and its slopes. */
INLINE VF face_wall_depth(VF x, VF y, VF* dzdx, VF* dzdy) {
  const VF p1 = 0.075f * x + 0.6f, p2 = 0.061f * y - 0.9f, p3 = 0.05f * (x + y) + 2.0f;
  const float hp = 1.57079633f; /* cos v = sin(v + pi/2) */
  const VF c3 = 0.8f * 0.05f * sin_poly(p3 + hp);
  *dzdx = 2.2f * 0.075f * sin_poly(p1 + hp) + c3;
  *dzdy = 1.6f * 0.061f * sin_poly(p2 + hp) + c3;
  return 41.0f + 2.2f * sin_poly(p1) + 1.6f * sin_poly(p2) + 0.8f * sin_poly(p3);
}

INLINE VF shape_f(VF x, VF y, VF z, VF* part) {
  VF sx, sy;
  const VF h = face_head(x, y, z, (VI)(0)), w = face_wall_depth(x, y, &sx, &sy) - z;
  *part = SEL(w < h, (VF)(1.0f), (VF)(0.0f));
  return fmin(h, w);
}

INLINE Local shape_local(VF x, VF y, VF z, float vox, VF* part) {
  const Local h = face_head_local(x, y, z, (VI)(0), vox);
  /* The wall's slopes are small and its curvature tiny: (z0 - z) / |grad| is
   * its distance to well under 0.1 voxel, and its foot point is p + w n. */
  VF sx, sy;
  const VF f = face_wall_depth(x, y, &sx, &sy) - z;
  const VF ig = 1.0f / sqrt(1.0f + sx * sx + sy * sy);
  Local w;
  w.d = f * ig * (1.0f / vox);
  w.nz = -ig;
  const VF k = -w.d * ig * SEED_UNIT;
  w.seed = SEL(fabs(w.d) < 1.0f, pack_seed(TO_INT(rint(sx * k)), TO_INT(rint(sy * k)), TO_INT(rint(-k))), (VU)(0u));
  *part = SEL(w.d < h.d, (VF)(1.0f), (VF)(0.0f));
  return local_min(h, w);
}

#elif SHAPE == 1 /* spine: a chain of vertebrae along x in soft tissue */

#define SPINE_COUNT 7
#define SPINE_PITCH 13.0f

/* One vertebra in its own frame: body centred at the origin, spinous process
 * toward -z (the transducer), transverse processes along +-y. */
INLINE VF vertebra(VF x, VF y, VF z) {
  const VF ay = fabs(y);
  VF d = sd_round_cylinder_x(x, y, z, 5.5f, 4.2f, 1.2f);                                 /* body */
  d = smin(d, sd_capsule(x, ay, z, 0.0f, 3.8f, -3.5f, 0.0f, 4.6f, -8.0f, 1.6f), 1.5f);  /* pedicles */
  d = smin(d, sd_capsule(x, ay, z, 0.0f, 4.6f, -8.0f, 0.5f, 0.0f, -10.5f, 1.6f), 1.5f); /* laminae */
  d = smin(d, sd_capsule(x, y, z, 0.5f, 0.0f, -10.5f, 3.0f, 0.0f, -19.0f, 1.8f), 1.5f); /* spinous */
  d = smin(d, sd_capsule(x, ay, z, 0.0f, 4.6f, -7.0f, 1.5f, 12.5f, -5.5f, 1.5f), 1.5f); /* transverse */
  return d;
}

/* Vertebra i (0 .. SPINE_COUNT - 1) placed along the chain. */
INLINE VF spine_vertebra(VF x, VF y, VF z, VI i) {
  const VF c = TO_FLOAT(i) - 0.5f * (SPINE_COUNT - 1);
  const VF xc = c * SPINE_PITCH;
  const VF zc = 5.0f + 0.005f * xc * xc; /* gentle curve, middle nearest the transducer */
  const VF s = 1.0f + 0.035f * c;        /* sizes grow along x */
  const VF is = 1.0f / s;
  return vertebra((x - xc) * is, y * is, (z - zc) * is) * s;
}
DEFINE_LOCAL_DISTANCE(spine_vertebra_local, spine_vertebra)

/* Limited domain repetition: the vertebra of p's cell and its nearer neighbour. */
INLINE void spine_cells(VF x, VI* i, VI* j) {
  const VF u = x * (1.0f / SPINE_PITCH) + 0.5f * (SPINE_COUNT - 1);
  *i = clamp(TO_INT(floor(u + 0.5f)), 0, SPINE_COUNT - 1);
  *j = clamp(SEL(u > TO_FLOAT(*i), *i + 1, *i - 1), 0, SPINE_COUNT - 1);
}

INLINE VF shape_f(VF x, VF y, VF z, VF* part) {
  VI i, j;
  spine_cells(x, &i, &j);
  *part = (VF)(2.0f);
  return fmin(spine_vertebra(x, y, z, i), spine_vertebra(x, y, z, j));
}

INLINE Local shape_local(VF x, VF y, VF z, float vox, VF* part) {
  VI i, j;
  spine_cells(x, &i, &j);
  *part = (VF)(2.0f);
  return local_min(spine_vertebra_local(x, y, z, i, vox), spine_vertebra_local(x, y, z, j, vox));
}

#else /* sphere */

INLINE VF shape_f(VF x, VF y, VF z, VF* part) {
  *part = (VF)(0.0f);
  return len3(x, y, z) - 30.0f;
}

INLINE Local shape_local(VF x, VF y, VF z, float vox, VF* part) {
  const VF r = len3(x, y, z), ir = 1.0f / fmax(r, 1e-6f);
  Local l;
  l.d = (r - 30.0f) * (1.0f / vox);
  l.nz = z * ir;
  const VF k = -l.d * ir * SEED_UNIT;
  l.seed = SEL(fabs(l.d) < 1.0f, pack_seed(TO_INT(rint(x * k)), TO_INT(rint(y * k)), TO_INT(rint(z * k))), (VU)(0u));
  *part = (VF)(0.0f);
  return l;
}

#endif

/* ---- materials ------------------------------------------------------------ */
/* ECHO: mean scattered power (soft tissue = 1); SPEC: amplitude of the
 * coherent boundary echo before |n.b|^3; REFL_DB: two-way reflection loss in
 * dB through a boundary facing the beam; ATTEN: two-way attenuation, dB/mm.
 * Outside the tissue: */
#if SHAPE == 1 /* soft tissue (muscle) around bone */
#define OUT_ECHO 0.10f
#define OUT_ATTEN 0.2f
#else /* amniotic / anechoic fluid */
#define OUT_ECHO 0.001f
#define OUT_ATTEN 0.01f
#endif
/* Inside, by part:   soft tissue, uterine wall / placenta, bone */
#define IN_ECHO       1.0f, 1.3f, 6.0f
#define IN_SPEC       2.5f, 1.5f, 6.0f
#define IN_REFL_DB    1.0f, 1.0f, 4.0f
#define IN_ATTEN      0.2f, 0.2f, 0.5f
INLINE VF by_part(VF part, float tissue, float wall, float bone) {
  return SEL(part > 1.5f, (VF)(bone), SEL(part > 0.5f, (VF)(wall), (VF)(tissue)));
}

/* Smooth low-frequency modulation of echogenicity, mean ~1. */
INLINE VF texture(VF x, VF y, VF z, VF w_in, uint key) {
  const VF t = 1.0f + 0.35f * value_noise(x * (1.0f / 6.0f), y * (1.0f / 6.0f), z * (1.0f / 6.0f), key);
#if SHAPE == 1 /* muscle: fibres along the spine (x) */
  const VF fib = 1.0f + 0.6f * value_noise(x * 0.10f, y * 0.35f, z * 0.8f, key ^ 0x85ebca6bu);
  return mixf(fib, t, w_in);
#else
  (void)w_in;
  return t;
#endif
}

/* Bone inside the tissue, 0..1: the fetal skull, a shell about 2.4 design
 * units thick 2 to 4.5 units under the scalp. Bright and attenuating, so the
 * brain below it lies in its shadow; the truth SDF ignores it (it is no
 * tissue / fluid boundary). */
#if SHAPE == 0
#define INNER_BONE_ECHO 10.0f
#define INNER_BONE_ATTEN 1.5f /* dB/mm, two-way */
INLINE VF inner_bone(VF x, VF y, VF z) {
  const VF s = sd_ellipsoid(x, y + 8.0f, z - 7.0f, 20.8f, 22.8f, 21.8f);
  return clampf(1.0f - fabs(s) * (1.0f / 1.2f), 0.0f, 1.0f);
}
#else
#define INNER_BONE_ECHO 0.0f
#define INNER_BONE_ATTEN 0.0f
INLINE VF inner_bone(VF x, VF y, VF z) {
  (void)x, (void)y, (void)z;
  return (VF)(0.0f);
}
#endif

/* ---- scene --------------------------------------------------------------- */
/* Each geometry kernel's work-item covers LANES neighbouring x voxels
 * starting at ix0; `count` of them lie inside the volume. */

#define SPEC_WIDTH 0.5f /* voxels: standard deviation of the boundary echo layer */
#define REDIST_RADIUS 6 /* voxels: window of each redistancing pass */
#define REDIST_SLACK 0.35f /* voxels: how much shorter than the seed bound a local estimate may be */

INLINE VF design_coord(VF i, int n, float vox) { return (i + 0.5f - 0.5f * (float)n) * vox; }

/* ---- pose (-D POSE: the randomised phantoms of phantom_scan.cl) ---------- */
/* A rigid motion of the whole scene: a point p of the volume (design units,
 * centred) lies at R^T (p - t) in the shape's own frame; pose.s0-s8 hold R
 * row-major, pose.s9-sb t. Distances are invariant, so the truth stays exact;
 * only the seeds (offsets to the surface) are rotated back into the volume's
 * frame, to 1/64 voxel. The normal_z kept in aux stays in the shape's frame
 * (phantom_scan.cl takes normals from the final distance instead). */
#ifdef POSE
#define POSE_ARG , const float16 pose
INLINE void to_object(const float16 pose, VF* x, VF* y, VF* z) {
  const VF dx = *x - pose.s9, dy = *y - pose.sa, dz = *z - pose.sb;
  *x = pose.s0 * dx + pose.s3 * dy + pose.s6 * dz;
  *y = pose.s1 * dx + pose.s4 * dy + pose.s7 * dz;
  *z = pose.s2 * dx + pose.s5 * dy + pose.s8 * dz;
}
INLINE VU seed_to_volume(const float16 pose, VU s) {
  const VF qx = TO_FLOAT(AS_INT(s << 22) >> 22), qy = TO_FLOAT(AS_INT(s << 12) >> 22), qz = TO_FLOAT(AS_INT(s << 2) >> 22);
  const VF wx = pose.s0 * qx + pose.s1 * qy + pose.s2 * qz;
  const VF wy = pose.s3 * qx + pose.s4 * qy + pose.s5 * qz;
  const VF wz = pose.s6 * qx + pose.s7 * qy + pose.s8 * qz;
  return SEL(AS_INT(s) < 0, pack_seed(TO_INT(rint(wx)), TO_INT(rint(wy)), TO_INT(rint(wz))), (VU)(0u));
}
#else
#define POSE_ARG
#endif

/* Local distance estimate (sign of f), normal_z and part packed as
 * nz + 4 part, and the seed of every voxel. */
__kernel void phantom_geometry(__global float* restrict sdf, __global float* restrict aux,
                               __global uint* restrict seed, const GridDesc g, const float vox POSE_ARG) {
  const int ix0 = get_global_id(0) * LANES, iy = get_global_id(1), iz = get_global_id(2);
  if (!grid_contains(g, ix0, iy, iz)) return;
  const size_t idx = grid_index(g, ix0, iy, iz);
  const int count = g.nx - ix0;
  const VF x = design_coord(TO_FLOAT(ix0 + LANE_INDEX), g.nx, vox);
  const VF y = (VF)(design_coord((VF)((float)iy), g.ny, vox));
  const VF z = (VF)(design_coord((VF)((float)iz), g.nz, vox));
  VF part;
#ifdef POSE
  VF ox = x, oy = y, oz = z;
  to_object(pose, &ox, &oy, &oz);
  const Local l = shape_local(ox, oy, oz, vox, &part);
  store_lanes_u(seed + idx, seed_to_volume(pose, l.seed), count);
#else
  const Local l = shape_local(x, y, z, vox, &part);
  store_lanes_u(seed + idx, l.seed, count);
#endif
  store_lanes(sdf + idx, l.d, count);
  store_lanes(aux + idx, l.nz + 4.0f * part, count);
}

/* Redistancing: every voxel takes, of the seeds held by the voxels within
 * REDIST_RADIUS along one axis, the one nearest to itself (re-expressed
 * relative to itself). Passes along x, y and z bring each voxel the nearest
 * seed in a (2 REDIST_RADIUS + 1)^3 box (up to the rare misses of separable
 * vector propagation). Voxels farther than REDIST_RADIUS + 2 by the local
 * estimate (a lower bound there) hold no seed, and work-items made only of
 * such voxels skip the search. Integer arithmetic throughout: exact on any
 * device. */
INLINE void seed_candidate(VU c, VI shift_x, VI shift_y, VI shift_z, VI* best_d2, VU* best) {
  VI qx = (AS_INT(c << 22) >> 22) + shift_x;
  VI qy = (AS_INT(c << 12) >> 22) + shift_y;
  VI qz = (AS_INT(c << 2) >> 22) + shift_z;
  const VI d2 = qx * qx + qy * qy + qz * qz;
  const VI take = (AS_INT(c) < 0) & (abs(qx) < 512) & (abs(qy) < 512) & (abs(qz) < 512) & (d2 < *best_d2);
  *best_d2 = SEL(take, d2, *best_d2);
  *best = SEL(take, pack_seed(qx, qy, qz), *best);
}

#define REDISTANCE_PASS(NAME, AXIS)                                                             \
  __kernel void NAME(__global const uint* restrict in, __global uint* restrict out,             \
                     __global const float* restrict est, const GridDesc g) {                    \
    const int ix0 = get_global_id(0) * LANES, iy = get_global_id(1), iz = get_global_id(2);    \
    if (!grid_contains(g, ix0, iy, iz)) return;                                                \
    const size_t idx = grid_index(g, ix0, iy, iz);                                             \
    const int count = g.nx - ix0;                                                              \
    VI best_d2 = (VI)(0x7fffffff);                                                             \
    VU best = (VU)(0u);                                                                        \
    /* Far from every surface: nothing to find, and no nearer voxel needs a    \
       seed routed through here (each intermediate voxel of a voxel's path to  \
       its nearest seed is at most as far from that seed as the voxel). */     \
    const VI near = fabs(load_lanes(est + idx, count)) < REDIST_RADIUS + 2.0f;                 \
    if (!ANY(near)) {                                                                          \
      store_lanes_u(out + idx, best, count);                                                   \
      return;                                                                                  \
    }                                                                                          \
    const int c = AXIS == 0 ? ix0 : (AXIS == 1 ? iy : iz);                                     \
    const int n = AXIS == 0 ? g.nx : (AXIS == 1 ? g.ny : g.nz);                                \
    const size_t stride = AXIS == 0 ? 1 : (AXIS == 1 ? (size_t)g.nx : (size_t)g.nx * g.ny);    \
    const int span = AXIS == 0 ? LANES - 1 : 0; /* lanes of an x pass reach LANES - 1 further */ \
    const VI zero = (VI)(0);                                                                   \
    if (c >= REDIST_RADIUS && c + span + REDIST_RADIUS < n && count >= LANES) {                \
      _Pragma("unroll") for (int k = -REDIST_RADIUS; k <= REDIST_RADIUS; ++k) {                \
        const VU cand = load_lanes_u(in + idx + (ptrdiff_t)k * (ptrdiff_t)stride, LANES);      \
        const VI sh = (VI)(k * (int)SEED_UNIT);                                               \
        seed_candidate(cand, AXIS == 0 ? sh : zero, AXIS == 1 ? sh : zero, AXIS == 2 ? sh : zero, \
                       &best_d2, &best);                                                       \
      }                                                                                        \
    } else {                                                                                   \
      for (int k = -REDIST_RADIUS; k <= REDIST_RADIUS; ++k) {                                  \
        const VI cc = c + k + (AXIS == 0 ? LANE_INDEX : zero); /* per-lane coordinate */       \
        const VI inside = (cc >= 0) & (cc < n);                                                \
        VU cand = (VU)(0u);                                                                    \
        if (AXIS != 0) {                                                                       \
          if (c + k >= 0 && c + k < n) cand = load_lanes_u(in + idx + (ptrdiff_t)k * (ptrdiff_t)stride, count); \
        } else {                                                                               \
          cand = load_lanes_shifted_u(in + idx - ix0, ix0 + k, n, count);                      \
        }                                                                                      \
        cand = SEL(inside, cand, (VU)(0u));                                                    \
        const VI sh = (VI)(k * (int)SEED_UNIT);                                               \
        seed_candidate(cand, AXIS == 0 ? sh : zero, AXIS == 1 ? sh : zero, AXIS == 2 ? sh : zero, \
                       &best_d2, &best);                                                       \
      }                                                                                        \
    }                                                                                          \
    /* Far lanes hold nothing even when a near lane made the item search, so  \
       the result does not depend on LANES. */                                 \
    store_lanes_u(out + idx, SEL(near, best, (VU)(0u)), count);                                \
  }

REDISTANCE_PASS(phantom_redistance_x, 0)
REDISTANCE_PASS(phantom_redistance_y, 1)
REDISTANCE_PASS(phantom_redistance_z, 2)

/* The final signed distance of a voxel from its local estimate and the
 * nearest seed the redistancing found. */
INLINE VF final_distance(VF est, VU sd) {
  const VI qx = AS_INT(sd << 22) >> 22, qy = AS_INT(sd << 12) >> 22, qz = AS_INT(sd << 2) >> 22;
  const VF dist = sqrt(TO_FLOAT(qx * qx + qy * qy + qz * qz)) * (1.0f / SEED_UNIT);
  /* The seed distance is an upper bound (seeds lie on the surface), too long
   * by up to ~0.3 voxel where seeds are sparse; the local estimate is exact to
   * second order where F is smooth but can go wrong near concave blends.
   * Keep the local one when the bound allows it, the bound otherwise. */
  const VF m = fabs(est);
  const VI keep = (m <= dist + 0.02f) & (m >= dist - REDIST_SLACK);
  /* Beyond REDIST_RADIUS a nearer seed may lie outside the window. */
  const VI found = (AS_INT(sd) < 0) & (dist <= (float)REDIST_RADIUS);
  return SEL(found, copysign(SEL(keep, m, dist), est), est);
}

#ifndef PHANTOM_SCAN /* the fixed physics' image kernels; phantom_scan.cl has its own */
/* Per voxel: the final signed distance (the redistanced seed distance where
 * a seed was found, the local estimate elsewhere), then the echo model: the
 * complex field (scatterers + specular echo) and the square root of the
 * voxel's two-way amplitude transmission. In place: aux becomes half_t and
 * the seed plane becomes the imaginary part (each item reads, then writes,
 * its own voxels). */
__kernel void phantom_echo(__global float* restrict sdf, __global float* restrict aux_then_half_t,
                           __global uint* restrict seed_then_im, __global float* restrict re, const GridDesc g,
                           const float vox, const float h_mm, const uint scatter_key, const uint texture_key,
                           const float specular, const float attenuation) {
  const int ix0 = get_global_id(0) * LANES, iy = get_global_id(1), iz = get_global_id(2);
  if (!grid_contains(g, ix0, iy, iz)) return;
  const size_t idx = grid_index(g, ix0, iy, iz);
  const int count = g.nx - ix0;
  const VI ix = ix0 + LANE_INDEX;
  const VF x = design_coord(TO_FLOAT(ix), g.nx, vox);
  const VF y = (VF)(design_coord((VF)((float)iy), g.ny, vox));
  const VF z = (VF)(design_coord((VF)((float)iz), g.nz, vox));

  const VF est = load_lanes(sdf + idx, count);
  const VF a = load_lanes(aux_then_half_t + idx, count);
  const VU sd = load_lanes_u(seed_then_im + idx, count);
  const VF part = rint(a * 0.25f), nz = a - 4.0f * part;
  const VF sdf_v = final_distance(est, sd);
  store_lanes(sdf + idx, sdf_v, count);

  const VF w_in = clampf(0.5f - sdf_v, 0.0f, 1.0f); /* partial-volume share of tissue */
  const VF bone = w_in * inner_bone(x, y, z); /* bone inside tissue (the fetal skull), not a truth boundary */
  const VF echo = (mixf((VF)(OUT_ECHO), by_part(part, IN_ECHO), w_in) + INNER_BONE_ECHO * bone) *
                  texture(x, y, z, w_in, texture_key);

  /* Boundary echo: a thin coherent layer, strong where the surface faces the beam. */
  const VF c = fabs(nz);
  const VF facing = c * c * c;
  const VF u = sdf_v * (1.0f / SPEC_WIDTH);
  const VF layer = exp2_poly(-0.72134752f * u * u); /* exp(-u^2 / 2) */
  const VF spec = specular * by_part(part, IN_SPEC) * facing * layer;

  VU ha = AS_UINT(ix), hb = (VU)((uint)iy), hc = (VU)((uint)iz), hd = (VU)(scatter_key);
  PCG4D(ha, hb, hc, hd);
  const VF amp = sqrt(echo) * 0.70710678f;
  store_lanes(re + idx, normal_v(ha, hb) * amp + spec, count);
  store_lanes_u(seed_then_im + idx, AS_UINT(normal_v(hc, hd) * amp), count);

  /* Two-way losses in dB: attenuation over this voxel's path plus reflection
   * at a boundary (the layer integrates to refl_db along a facing path). */
  const VF atten = mixf((VF)(OUT_ATTEN), by_part(part, IN_ATTEN), w_in) + INNER_BONE_ATTEN * bone;
  const VF loss_db = attenuation * atten * h_mm +
                     specular * by_part(part, IN_REFL_DB) * facing * c * layer * (0.39894228f / SPEC_WIDTH);
  store_lanes(aux_then_half_t + idx, exp2_poly(loss_db * -0.08304820f), count); /* sqrt(10^(-dB/20)) */
}

#endif /* PHANTOM_SCAN */

/* Eight neighbouring (x, y) beams per work-item, marching along +z: an echo
 * from depth z is weakened by everything between it and the transducer (both
 * ways), so deep tissue darkens and strong reflectors cast shadows. Explicit
 * float8: a loop inside a work-item is never vectorised by PoCL. */
__kernel void phantom_attenuate(__global float* restrict re, __global float* restrict im,
                                __global const float* restrict half_t, const GridDesc g) {
  const int x0 = 8 * get_global_id(0), y = get_global_id(1);
  if (x0 >= g.nx || y >= g.ny) return;
  const size_t stride = (size_t)g.nx * (size_t)g.ny;
  const size_t start = (size_t)x0 + (size_t)g.nx * (size_t)y;
  if (x0 + 8 <= g.nx) {
    float8 t = (float8)(1.0f);
    size_t i = start;
    for (int z = 0; z < g.nz; ++z, i += stride) {
      const float8 ht = vload8(0, half_t + i);
      t *= ht; /* half of this voxel's own loss: its echo comes from its centre */
      vstore8(vload8(0, re + i) * t, 0, re + i);
      vstore8(vload8(0, im + i) * t, 0, im + i);
      t = fmax(t * ht, (float8)(1e-12f)); /* no denormals deep in a shadow */
    }
  } else {
    for (int x = x0; x < g.nx; ++x) {
      float t = 1.0f;
      size_t i = start + (size_t)(x - x0);
      for (int z = 0; z < g.nz; ++z, i += stride) {
        const float ht = half_t[i];
        t *= ht;
        re[i] *= t;
        im[i] *= t;
        t = fmax(t * ht, 1e-12f);
      }
    }
  }
}

#ifndef PHANTOM_SCAN
/* ---- point-spread function: separable Gaussian on the complex field ------- */
/* Same structure as filter.cl (measurements there): weights in registers
 * first, compile-time radius, clamp-free interior; real and imaginary parts
 * are separate float planes so PoCL vectorises across work-items. The
 * boundary repeats the edge sample. */
#define PSF_PASS(NAME, R, COORD, EXTENT, STRIDE)                                                \
  __kernel void NAME(__global const float* restrict in_re, __global const float* restrict in_im, \
                     __global float* restrict out_re, __global float* restrict out_im,           \
                     __constant const float* restrict w, const GridDesc g) {                     \
    float wk[2 * R + 1];                                                                         \
    _Pragma("unroll") for (int k = 0; k <= 2 * R; ++k) wk[k] = w[k];                             \
    const int x = get_global_id(0), y = get_global_id(1), z = get_global_id(2);                 \
    if (!grid_contains(g, x, y, z)) return;                                                      \
    const size_t idx = grid_index(g, x, y, z);                                                   \
    const int c = COORD;                                                                         \
    const int n = EXTENT;                                                                        \
    const size_t stride = STRIDE;                                                                \
    float ar = 0.0f, ai = 0.0f;                                                                  \
    if (c >= R && c + R < n) {                                                                   \
      const size_t base = idx - (size_t)R * stride;                                              \
      _Pragma("unroll") for (int k = 0; k <= 2 * R; ++k) {                                       \
        ar = fma(wk[k], in_re[base + (size_t)k * stride], ar);                                   \
        ai = fma(wk[k], in_im[base + (size_t)k * stride], ai);                                   \
      }                                                                                          \
    } else {                                                                                     \
      const size_t base = idx - (size_t)c * stride;                                              \
      _Pragma("unroll") for (int k = -R; k <= R; ++k) {                                          \
        const size_t j = base + (size_t)clamp(c + k, 0, n - 1) * stride;                         \
        ar = fma(wk[k + R], in_re[j], ar);                                                       \
        ai = fma(wk[k + R], in_im[j], ai);                                                       \
      }                                                                                          \
    }                                                                                            \
    out_re[idx] = ar;                                                                            \
    out_im[idx] = ai;                                                                            \
  }

#if LANES == 1
PSF_PASS(phantom_psf_x, RADIUS_LATERAL, x, g.nx, 1)
#else
/* The x pass with explicit vectors: LANES outputs per work-item, each tap one
 * unaligned vector load (PoCL's own vectorisation of the generic pass is 2.5x
 * slower here: neighbouring work-items disagree on the interior test). */
__kernel void phantom_psf_x(__global const float* restrict in_re, __global const float* restrict in_im,
                            __global float* restrict out_re, __global float* restrict out_im,
                            __constant const float* restrict w, const GridDesc g) {
  float wk[2 * RADIUS_LATERAL + 1];
#pragma unroll
  for (int k = 0; k <= 2 * RADIUS_LATERAL; ++k) wk[k] = w[k];
  const int ix0 = get_global_id(0) * LANES, y = get_global_id(1), z = get_global_id(2);
  if (!grid_contains(g, ix0, y, z)) return;
  const size_t idx = grid_index(g, ix0, y, z);
  const int count = g.nx - ix0;
  VF ar = (VF)(0.0f), ai = (VF)(0.0f);
  if (ix0 >= RADIUS_LATERAL && ix0 + LANES - 1 + RADIUS_LATERAL < g.nx) {
    const size_t base = idx - RADIUS_LATERAL;
#pragma unroll
    for (int k = 0; k <= 2 * RADIUS_LATERAL; ++k) {
      ar = fma((VF)(wk[k]), VLOAD(in_re + base + k), ar);
      ai = fma((VF)(wk[k]), VLOAD(in_im + base + k), ai);
    }
  } else {
    const size_t row = idx - ix0;
    float tr[LANES], ti[LANES];
    for (int l = 0; l < LANES; ++l) {
      float sr = 0.0f, si = 0.0f;
      for (int k = -RADIUS_LATERAL; k <= RADIUS_LATERAL; ++k) {
        const size_t j = row + (size_t)clamp(ix0 + l + k, 0, g.nx - 1);
        sr = fma(wk[k + RADIUS_LATERAL], in_re[j], sr);
        si = fma(wk[k + RADIUS_LATERAL], in_im[j], si);
      }
      tr[l] = sr;
      ti[l] = si;
    }
    ar = VLOAD_PRIVATE(tr);
    ai = VLOAD_PRIVATE(ti);
  }
  store_lanes(out_re + idx, ar, count);
  store_lanes(out_im + idx, ai, count);
}
#endif
PSF_PASS(phantom_psf_y, RADIUS_LATERAL, y, g.ny, (size_t)g.nx)
PSF_PASS(phantom_psf_z, RADIUS_AXIAL, z, g.nz, (size_t)g.nx * (size_t)g.ny)

/* ---- B-mode -------------------------------------------------------------- */
/* Electronic noise (complex Gaussian, rms `noise` in tissue units) added to
 * the beamformed signal, envelope |I + iQ|, then log compression:
 *   v = 255 * (1 + (20 log10 |s| - top_db) / range_db), clamped to [0, 255].
 * top_db is the level (dB re the mean tissue echo) that maps to 255. */
__kernel void phantom_bmode(__global const float* restrict re, __global const float* restrict im,
                            __global uchar* restrict out, const GridDesc g, const uint noise_key,
                            const float noise, const float top_db, const float range_db) {
  const int ix0 = get_global_id(0) * LANES, iy = get_global_id(1), iz = get_global_id(2);
  if (!grid_contains(g, ix0, iy, iz)) return;
  const size_t idx = grid_index(g, ix0, iy, iz);
  const int count = g.nx - ix0;
  VU a = AS_UINT(ix0 + LANE_INDEX), b = (VU)((uint)iy), c = (VU)((uint)iz), d = (VU)(noise_key);
  PCG4D(a, b, c, d);
  const float sn = noise * 0.70710678f;
  const VF i_ = load_lanes(re + idx, count) + normal_v(a, b) * sn;
  const VF q_ = load_lanes(im + idx, count) + normal_v(c, d) * sn;
  const VF power = fmax(i_ * i_ + q_ * q_, 1e-30f);
  const VF db = 3.01029996f * log2_poly(power); /* 10 log10 */
  const VF v = 255.0f * (1.0f + (db - top_db) / range_db);
  store_lanes_b(out + idx, TO_UCHAR(clampf(rint(v), 0.0f, 255.0f)), count);
}

#endif /* PHANTOM_SCAN */

/* The raw implicit function (voxels, negative inside) at n points given in
 * voxel coordinates (three planes padded to a multiple of LANES): for tests
 * of the distance correction. */
__kernel void phantom_implicit(__global const float* restrict px, __global const float* restrict py,
                               __global const float* restrict pz, __global float* restrict f, const GridDesc g,
                               const float vox, const uint n POSE_ARG) {
  const uint i0 = get_global_id(0) * LANES;
  if (i0 >= n) return;
#if LANES == 8
  const VF qx = vload8(0, px + i0), qy = vload8(0, py + i0), qz = vload8(0, pz + i0);
#else
  const VF qx = px[i0], qy = py[i0], qz = pz[i0];
#endif
  VF part;
  VF x = (qx + 0.5f - 0.5f * (float)g.nx) * vox, y = (qy + 0.5f - 0.5f * (float)g.ny) * vox,
     z = (qz + 0.5f - 0.5f * (float)g.nz) * vox;
#ifdef POSE
  to_object(pose, &x, &y, &z);
#endif
  const VF v = shape_f(x, y, z, &part);
  store_lanes(f + i0, v * (1.0f / vox), (int)(n - i0));
}
