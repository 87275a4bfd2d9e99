#!/usr/bin/env python3
"""The cross-check's baseline (docs/crosscheck.md): what a user does without softshell -- the
data normalised by robust statistics (1st and 99.5th percentiles of the scanned samples), a
Gaussian lowpass of 1 mm, and Levoy's isovalue-contour opacity (transition 1 voxel) at one
fixed isovalue per anatomy, chosen on the training seeds. The unscanned zero fill (a solid
5 x 5 x 5 opening of exact zeros, grown by 2 voxels) is held at 0, as softshell's mask does.

usage: levoy.py CASE_DIR T[,T...] [SIGMA_MM]   -> CASE_DIR/u_lvT.nrrd for each isovalue T
"""
import sys
import numpy as np
from scipy import ndimage

from nrrd_raw import read

d = sys.argv[1]
ts = [float(t) for t in sys.argv[2].split(',')]
sig = float(sys.argv[3]) if len(sys.argv) > 3 else 1.0

_, v, sp = read(d + '/volume.nrrd')
v = v.astype(np.float32)
truth_hdr, _, _ = read(d + '/truth_sdf.nrrd')
solid = ndimage.binary_opening(v == 0, np.ones((5, 5, 5)))
mask = ndimage.binary_dilation(solid, iterations=2)
lo, hi = np.percentile(v[~mask], [1, 99.5])
vn = np.clip((v - lo) / (hi - lo), 0, 1.2)
vs = ndimage.gaussian_filter(vn, [sig / sp[2], sig / sp[1], sig / sp[0]]) if sig > 0 else vn
g = np.sqrt(sum(np.gradient(vs, axis=a) ** 2 for a in range(3)))
for t in ts:
    u = np.clip(1 - np.abs(t - vs) / (g + 1e-6), 0, 1)
    u[mask] = 0
    with open('%s/u_lv%.2f.nrrd' % (d, t), 'wb') as f:
        f.write(truth_hdr)
        f.write(u.astype(np.float32).tobytes())
