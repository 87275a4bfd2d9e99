#!/usr/bin/env python3
"""An oracle for a data-side bone rule, not built into softshell (docs/parameters.md, "Shadows
filled under bone echoes: an oracle"): under an echo over an acoustic shadow, replace the shadow
(and the echo's lower flank down to it) by the tissue's level at that depth, so that only the
echo's ridge is left for the classifier to draw. Run by hand on a cross-check case; classify and
evaluate the written volume as bench/crosscheck/run.sh does.

- v~: the data lowpassed by 1.25 mm; an echo is v~ above its 97th percentile (scanned samples).
- dark: the data lowpassed by 1 mm under half the median of v~.
- a shadow: a 6-connected dark component with a voxel at most REACH mm (default 3) under an
  echo voxel of its own beam line (along z; a fan's beams are not followed).
- the flank: on a line, the voxels between its last echo voxel and the shadow under it, when
  that shadow starts at most REACH mm down.
- the fill: the median of the plane's scanned samples outside the fill.

usage: shadow_fill.py IN.nrrd OUT.nrrd [REACH_MM]
"""
import sys
import numpy as np
from scipy import ndimage

from nrrd_raw import read

head, raw, sp = read(sys.argv[1])
reach = float(sys.argv[3]) if len(sys.argv) > 3 else 3.0
v = raw.astype(np.float64)
scanned = v > 0 if raw.dtype != np.float32 else np.ones(v.shape, bool)


def lowpass(mm):
    return ndimage.gaussian_filter(v, [mm / sp[2], mm / sp[1], mm / sp[0]])


vs, vl = lowpass(1.25), lowpass(1.0)
echo = vs > np.percentile(vs[scanned], 97)
dark = (vl < 0.5 * np.median(vs[scanned])) & scanned
nz = v.shape[0]
near = int(np.ceil(reach / sp[2]))
z = np.arange(nz)[:, None, None]
last_echo = np.maximum.accumulate(np.where(echo, z, -10**6), axis=0)
seed = dark & (z - last_echo <= near)
lab, _ = ndimage.label(dark)
keep = np.zeros(lab.max() + 1, bool)
keep[np.unique(lab[seed])] = True
keep[0] = False
shadow = keep[lab]
next_shadow = np.minimum.accumulate(np.where(shadow, z, nz)[::-1], axis=0)[::-1]
flank = ~echo & (last_echo >= 0) & (z > last_echo) & (next_shadow < nz) & (next_shadow - last_echo <= near) & (z < next_shadow)
fill = (shadow | flank) & scanned
level = np.array([np.median(v[k][scanned[k] & ~fill[k]]) if (scanned[k] & ~fill[k]).any() else 0.0 for k in range(nz)])
out = v.copy()
out[fill] = np.broadcast_to(level[:, None, None], v.shape)[fill]
print('filled %.2f %% of the voxels' % (100 * fill.mean()), file=sys.stderr)
if raw.dtype != np.float32:
    out = np.clip(np.rint(out), 0, np.iinfo(raw.dtype).max)
open(sys.argv[2], 'wb').write(head + out.astype(raw.dtype).tobytes())
