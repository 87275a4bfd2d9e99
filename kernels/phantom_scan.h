/* Parameter block of the randomised-physics phantom (phantom_scan.cl), shared
 * by the host (host/phantom_scan.cpp fills it) and the kernels: one float
 * array, these are the indices. Units: mm, radians, dB, power ratios; the
 * meaning of each physical parameter is in docs/phantom.md.
 */
#ifndef SOFTSHELL_PHANTOM_SCAN_H
#define SOFTSHELL_PHANTOM_SCAN_H

/* Beam geometry. The world frame (mm): x, y centred on the volume, z the
 * depth below the top face (voxel (i, j, k) at ((i + 0.5 - nx / 2) h,
 * (j + 0.5 - ny / 2) h, (k + 0.5) h)). Beam grid cell (u, v, w): */
#define PS_KIND 0        /* 0 linear (u, v, w) = voxel; 1 fan: apex line x = 0, z = -R along y; 2 fan3d: apex point (0, 0, -R) */
#define PS_H 1           /* voxel spacing, mm */
#define PS_R 2           /* probe radius: the apex lies R above the top face; beam depth d = r - R */
#define PS_DTH_X 3       /* fans: angular step of the beam grid along u (radians) */
#define PS_DTH_Y 4       /* fan3d: angular step along v */
#define PS_DR 5          /* radial (depth) step of the beam grid, mm */
#define PS_TAN_X 6       /* fans: tan of the sector's half-angle in x */
#define PS_TAN_Y 7       /* fan3d: tan of the half-angle in y */
#define PS_DEPTH 8       /* scan depth D below the probe surface, mm */
#define PS_DESIGN 9      /* design units per mm (100 / fov) */
#define PS_POSE 10       /* 12 floats: R row-major (9), t (3, design units) */
/* Materials: echo = mean scattered power (soft tissue 1), SPEC = boundary
 * echo amplitude, REFL = two-way reflection loss (dB) through a facing
 * boundary, ATT = two-way attenuation (dB/mm). By part: tissue, wall, bone. */
#define PS_E_BG 22
#define PS_E_PART 23     /* 3 */
#define PS_E_SKULL 26
#define PS_SPEC_PART 27  /* 3 */
#define PS_REFL_PART 30  /* 3 */
#define PS_ATT_BG 33
#define PS_ATT_PART 34   /* 3 */
#define PS_ATT_SKULL 37
#define PS_TEXTURE 38    /* texture amplitude */
#define PS_RHO 39        /* point scatterers per mm^3 */
#define PS_SPEC_W 40     /* width (sd, mm) of the boundary echo layer */
/* Near field (layers under the probe, along the beam depth d). */
#define PS_NF 41         /* 1: present */
#define PS_NF_B 42       /* 3: depths of the skin/fat, fat/muscle and muscle/below interfaces, mm */
#define PS_NF_WAVE 45    /* relative undulation of the interfaces */
#define PS_NF_K 46       /* 4: two wave vectors (rad/mm) over the lateral coordinates */
#define PS_NF_PHASE 50   /* 8: phases of the two waves for the surface and interfaces 1-3 */
#define PS_NF_E 58       /* 3: echo of skin, fat, muscle */
#define PS_NF_SPEC 61    /* interface (fascia) echo amplitude */
#define PS_NF_REFL 62    /* two-way reflection loss per interface, dB */
#define PS_NF_ATT 63     /* 3: two-way attenuation of skin, fat, muscle, dB/mm */
#define PS_NF_REVERB 66  /* amplitude ratio of each further reverberation */
/* Acquisition and display. */
#define PS_JITTER 67     /* freehand sweep: peak in-plane displacement of a slice, mm */
#define PS_NOISE 68      /* electronic noise rms amplitude (tissue 1) */
#define PS_DR_DB 69      /* dynamic range, dB */
#define PS_TOP_DB 70     /* level mapped to 255, dB re the mean tissue echo */
#define PS_ATT_REF 71    /* the reference (soft) tissue's two-way attenuation, dB/mm: what the TGC restores */
#define PS_COUNT 72

/* shadow_db outside the scanned region: no beam went there, nothing there can
 * be seen (a finite stand-in for an infinite loss). */
#define UNSCANNED_LOSS_DB 1000.0f

#endif
