"""The cross-check's volumes as the simulator writes them (indsim.py): one attached raw NRRD
header with axis-aligned space directions (and softshell's own phantoms, whose uint8 type is
spelled "unsigned char"). Shared by the hand-run tools (levoy.py, shadow_fill.py,
crest_move.py)."""
import re

import numpy as np


def read(fn):
    """Returns (the header's bytes with its blank line, the samples as a (z, y, x) array, the
    spacing x, y, z in mm)."""
    raw = open(fn, 'rb').read()
    i = raw.index(b'\n\n') + 2
    hdr = raw[:i].decode('latin1')
    typ = re.search(r'type: ([^\n]+)', hdr).group(1).strip()
    dims = [int(x) for x in re.search(r'sizes: (\d+) (\d+) (\d+)', hdr).groups()]
    sp = [float(x) for x in re.search(r'\(([-0-9.e]+),0,0\) \(0,([-0-9.e]+),0\) \(0,0,([-0-9.e]+)\)', hdr).groups()]
    dt = {'uchar': np.uint8, 'unsigned char': np.uint8, 'uint8': np.uint8, 'ushort': np.uint16,
          'unsigned short': np.uint16, 'uint16': np.uint16, 'float': np.float32}[typ]
    return raw[:i], np.frombuffer(raw[i:], dtype=dt).reshape(dims[::-1]), sp
