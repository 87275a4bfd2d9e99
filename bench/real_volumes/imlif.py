# IMLiF: where the splats (u > 0.2) lie along the beam (y): above the
# reflector (y < 55, water), on it (55-72: its echo 59-70), between it and
# the first ghost (73-83), on the ghosts (>= 84: copies at 88-91, 119-120,
# ~148); and within 1 mm (10 voxels along x) of the fan's side (zero fill).
import sys
sys.path.insert(0, sys.path[0]); from measure import read_any
dims,sp,off,v = read_any(sys.argv[1]); nx,ny,nz = dims
for path in sys.argv[2:]:
    _,_,_,u = read_any(path)
    c = [0,0,0,0]; side = 0; tot = 0
    for z in range(nz):
        for y in range(ny):
            row = (z*ny+y)*nx
            for x in range(nx):
                if u[row+x] <= 0.2: continue
                tot += 1
                c[0 if y < 55 else 1 if y <= 72 else 2 if y < 84 else 3] += 1
                if any(v[row+xx] == 0 for xx in range(max(0,x-10), min(nx,x+11))): side += 1
    t = max(tot,1)
    print("| %s | %d | %.1f %% | %.1f %% | %.1f %% | %.1f %% | %.1f %% |" % (path.split('-')[-1].split('.')[0], tot, 100.*c[0]/t, 100.*c[1]/t, 100.*c[2]/t, 100.*c[3]/t, 100.*side/t))
