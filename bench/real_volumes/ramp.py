# Slicer-style: opacity ramp on the 1 mm lowpassed data from iso up a quarter
# of the way to its 99th percentile (scanned = nonzero input), unscanned 0;
# writes a float nrrd like classify's.
import sys, struct
sys.path.insert(0, sys.path[0]); from measure import read_any
inp, lp, iso, out = sys.argv[1], sys.argv[2], float(sys.argv[3]), sys.argv[4]
dims,sp,off,v = read_any(inp); _,_,_,l = read_any(lp)
vals = sorted(l[i] for i in range(len(v)) if v[i])
p99 = vals[int(0.99*(len(vals)-1))]
w = max(1e-6, 0.25*(p99-iso))
u = [0.0 if not v[i] else min(1.0, max(0.0, (l[i]-iso)/w)) for i in range(len(v))]
hdr = open(lp,'rb').read().split(b'\n\n')[0].decode()
hdr = '\n'.join(('encoding: raw' if h.startswith('encoding') else h) for h in hdr.split('\n') if not h.startswith('data file'))
hdr = '\n'.join(('type: float\nendian: little' if h.startswith('type') else h) for h in hdr.split('\n') if not h.startswith('endian'))
open(out,'wb').write((hdr+'\n\n').encode()+struct.pack('<%df'%len(u),*u))
print("ramp %.1f .. %.1f" % (iso, iso+w))
