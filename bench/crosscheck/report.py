#!/usr/bin/env python3
"""Tables of the cross-check (docs/crosscheck.md).

report.py choose OUT "SEEDS"          the baseline's isovalue per anatomy: best mean F1 visible
report.py table OUT "SEEDS" TAG...    worst case (mean) per anatomy over SEEDS, per method
report.py cases OUT "SEEDS" TAG_A TAG_B   cases whose F1 visible differs between two runs
"""
import glob, json, os, sys
import numpy as np

mode, out, seeds = sys.argv[1], sys.argv[2], sys.argv[3].split()
SHAPES = ('head', 'bone', 'cyst')


def ev(d, t):
    try:
        return json.load(open('%s/ev_%s.json' % (d, t)))
    except (OSError, ValueError):
        return None


def f1(d, t):
    e = ev(d, t)
    return float('nan') if e is None else (e['f1_visible'] or 0.0)


def dirs(sh):
    return ['%s/%s%s' % (out, sh, s) for s in seeds]


if mode == 'choose':
    for sh in SHAPES:
        tags = sorted({os.path.basename(f)[3:-5] for f in glob.glob('%s/%s*/ev_lv*.json' % (out, sh))})
        m = {t: np.nanmean([f1(d, t) for d in dirs(sh)]) for t in tags}
        best = max(m, key=m.get)
        print(sh, best[2:], '%.3f' % m[best])
elif mode == 'table':
    lv = dict(l.split()[:2] for l in open(out + '/baseline.txt'))
    keys = [('f1_visible', 'F1 visible', min), ('precision', 'precision', min),
            ('recall_visible', 'recall visible', min), ('blobs6', 'blobs6', max),
            ('normal_error_deg', 'normal (deg)', max), ('surface_peak_visible', 'peak visible', min),
            ('percent_opaque', '% opaque', max),
            ('shell_offset_mm', 'offset (mm)', lambda xs: xs[np.argmax(np.abs(xs))])]
    print('| anatomy (cases) | method | ' + ' | '.join(k[1] for k in keys) + ' |')
    print('|' + '---|' * (len(keys) + 2))
    for sh in SHAPES:
        ds = dirs(sh)
        for t in sys.argv[4:] + ['lv' + lv[sh]]:
            cells = []
            for k, _, worst in keys:
                x = np.array([(ev(d, t) or {}).get(k) for d in ds], dtype=float)
                # A null (nothing drawn, no visible surface) counts as 0 for the scores.
                xs = x[~np.isnan(x)] if k in ('normal_error_deg', 'shell_offset_mm') else np.nan_to_num(x, nan=0.0)
                cells.append('%.3g (%.3g)' % (worst(xs), np.mean(xs)) if len(xs) else '-')
            name = ('lowpass 1 mm + Levoy at %s (chosen on the training seeds)' % lv[sh]) if t.startswith('lv') else t
            print('| %s (%d) | %s | %s |' % (sh, len(ds), name, ' | '.join(cells)))
    print('\nEach cell: worst case over the cases (mean in brackets); offset: the largest |shell_offset_mm|.')
    missing = ['%s (%s)' % (os.path.basename(d), t) for sh in SHAPES for d in dirs(sh) for t in sys.argv[4:]
               if ev(d, t) is None]
    if missing:
        print('No evaluation (classify or evaluate failed; scored as nothing drawn): ' + ', '.join(missing))
elif mode == 'cases':
    a, b = sys.argv[4], sys.argv[5]
    for sh in SHAPES:
        for d in dirs(sh):
            fa, fb = f1(d, a), f1(d, b)
            if abs(fa - fb) > 1e-9:
                print('%s %.3f -> %.3f (%+.3f)' % (os.path.basename(d), fa, fb, fb - fa))
