# Share of the splats of volume A lying within R mm (world coordinates) of a
# splat of volume B: is the LNMEAN crop's drawn set the bone the full sweep draws?
import sys, math
sys.path.insert(0, sys.path[0]); from measure import read_any
def splats(inp, u):
    dims,sp,off,_ = read_any(inp); _,_,_,uu = read_any(u); nx,ny,nz = dims
    pts = []
    for i,a in enumerate(uu):
        if a > 0.2:
            x = i % nx; y = (i // nx) % ny; z = i // (nx*ny)
            pts.append((off[0]+x*sp[0], off[1]+y*sp[1], off[2]+z*sp[2]))
    return pts, sp[0]
A, h = splats(sys.argv[1], sys.argv[2]); B, _ = splats(sys.argv[3], sys.argv[4]); R = float(sys.argv[5])
cell = {}
for p in B: cell.setdefault(tuple(int(math.floor(c/R)) for c in p), []).append(p)
near = 0
for p in A:
    k = tuple(int(math.floor(c/R)) for c in p); hit = False
    for dx in (-1,0,1):
        for dy in (-1,0,1):
            for dz in (-1,0,1):
                for q in cell.get((k[0]+dx,k[1]+dy,k[2]+dz), ()):
                    if (p[0]-q[0])**2+(p[1]-q[1])**2+(p[2]-q[2])**2 <= R*R: hit = True; break
                if hit: break
            if hit: break
        if hit: break
    near += hit
print("%d of %d splats (%.1f %%) within %.1f mm of one of %d" % (near, len(A), 100.0*near/max(1,len(A)), R, len(B)))
