#!/usr/bin/env python3
"""An oracle for a shell-side bone rule, not built into softshell (docs/parameters.md, "Shells
moved up to the echo's crest: an oracle"): where the classifier drew a bone echo's lower flank
(the fall from the echo into its shadow), put the opacity on the echo's crest instead. It
changes a finished u, not the data or the classifier. Run by hand on a cross-check case (or a
family phantom), then evaluate the written u as bench/crosscheck/run.sh does.

Along each beam line (z; a fan's beams are not followed):
- v~: the data lowpassed by 1 mm.
- a run: a stretch of the line with u > 0.05; its centre the u-weighted mean depth.
- a falling run: at its centre v~ falls with depth, the fall at least half of |grad v~|.
- its crest: the brightest v~ up to REACH mm (default 3) up the line from the centre.
- a ridge: the crest stands over the data up to 2 mm above it by at least RIDGE (default 0.25)
  of its height over the data up to 2 mm under the centre (a thin echo; a cyst's top wall, a step
  down from tissue, has no such crest).
- move: a falling run on a ridge is moved up by (centre - crest), taking the larger value where
  it lands; fill: it is stretched up to the crest instead (every sample from the moved run's top
  to the run's bottom at the run's peak), which keeps the shell in one piece.

usage: crest_move.py CASE_DIR U_IN.nrrd U_OUT.nrrd [move|fill] [RIDGE] [REACH_MM]
"""
import sys
import numpy as np
from scipy import ndimage

from nrrd_raw import read

case, u_in, u_out = sys.argv[1:4]
mode = sys.argv[4] if len(sys.argv) > 4 else 'move'
ridge = float(sys.argv[5]) if len(sys.argv) > 5 else 0.25
reach_mm = float(sys.argv[6]) if len(sys.argv) > 6 else 3.0
if mode not in ('move', 'fill'):
    print('crest_move.py: the mode is move or fill, not ' + mode, file=sys.stderr)
    sys.exit(2)

_, raw, sp = read(case + '/volume.nrrd')
u_head, u, _ = read(u_in)
u = u.astype(np.float32)
vs = ndimage.gaussian_filter(raw.astype(np.float32), [1.0 / sp[2], 1.0 / sp[1], 1.0 / sp[0]])
gz = np.gradient(vs, axis=0) / sp[2]
gn = np.sqrt(gz ** 2 + (np.gradient(vs, axis=1) / sp[1]) ** 2 + (np.gradient(vs, axis=2) / sp[0]) ** 2)
reach, r2 = int(round(reach_mm / sp[2])), int(round(2.0 / sp[2]))
nz, ny, nx = u.shape
out = np.zeros_like(u)
runs = moved = 0
for y in range(ny):
    for x in range(nx):
        col = u[:, y, x]
        if col.max() <= 0.05:
            continue
        lab, n = ndimage.label(col > 0.05)
        for r in range(1, n + 1):
            idx = np.nonzero(lab == r)[0]
            w = col[idx]
            zc = int(round((idx * w).sum() / w.sum()))
            runs += 1
            shift = 0
            if gz[zc, y, x] < 0 and -gz[zc, y, x] >= 0.5 * gn[zc, y, x]:
                lo = max(0, zc - reach)
                zcrest = lo + int(np.argmax(vs[lo:zc + 1, y, x]))
                crest = vs[zcrest, y, x]
                above = vs[max(0, zcrest - r2):zcrest + 1, y, x].min()
                below = vs[zc:min(nz, zc + r2 + 1), y, x].min()
                if crest - above >= ridge * (crest - below):
                    shift = zc - zcrest
            moved += shift > 0
            tgt = idx - shift
            out[tgt, y, x] = np.maximum(out[tgt, y, x], w)
            if mode == 'fill' and shift > 0:
                z0, z1 = int(tgt.min()), int(idx.max())
                out[z0:z1 + 1, y, x] = np.maximum(out[z0:z1 + 1, y, x], w.max())
with open(u_out, 'wb') as f:
    f.write(u_head)
    f.write(out.astype(np.float32).tobytes())
print('%s: %d runs, %d moved up to a crest (%s)' % (case, runs, moved, mode))
