# Splats (u > 0.2) in the first 8 mm below the skin line along the beam, and
# the splats' share of the scanned (nonzero input) voxels.
import sys, struct, gzip, re
def read_any(path):
    b=open(path,'rb').read()
    if path.endswith('.mha'):
        i=b.index(b'ElementDataFile = LOCAL\n')+len(b'ElementDataFile = LOCAL\n')
        hdr=b[:i].decode(errors='replace')
        dims=[int(t) for t in re.search(r'DimSize = ([\d ]+)',hdr).group(1).split()]
        sp=[float(t) for t in re.search(r'ElementSpacing = ([\d. ]+)',hdr).group(1).split()]
        off=[float(t) for t in re.search(r'Offset = ([-\d. ]+)',hdr).group(1).split()]
        data=b[i:]
        if 'CompressedData = True' in hdr:
            import zlib; data=zlib.decompress(data)
        return dims, sp, off, data
    i=b.index(b'\n\n'); hdr=b[:i].decode(); data=b[i+2:]
    if 'encoding: gzip' in hdr: data=gzip.decompress(data)
    t=re.search(r'type: (.*)',hdr).group(1).strip()
    if t in ('uchar','unsigned char','uint8','uint8_t'): return None,None,None,data
    return None,None,None,struct.unpack('<%df'%(len(data)//4),data)
def stats(inp, u, beam, thr=0.2, scanned=0):
    dims,sp,off,v=read_any(inp); _,_,_,uu=read_any(u)
    nx,ny,nz=dims; h=sp[beam]
    if not scanned: scanned=sum(1 for c in v if c)
    splats=0; near=0
    st=[1,nx,nx*ny]; ax=beam; lat=[a for a in range(3) if a!=ax]
    for a in range(dims[lat[0]]):
        for b in range(dims[lat[1]]):
            base=a*st[lat[0]]+b*st[lat[1]]
            skin=None
            for p in range(dims[ax]):
                i=base+p*st[ax]
                if skin is None and v[i]: skin=p
                if uu[i]>thr:
                    splats+=1
                    if skin is not None and (p-skin)*h<8.0: near+=1
    return splats, near, scanned
if __name__=='__main__':
    s,n,sc=stats(sys.argv[1],sys.argv[2],int(sys.argv[3]), 0.2, int(sys.argv[4]) if len(sys.argv)>4 else 0)
    print("%.1f %% / %.1f %% (%d)" % (100.0*n/max(s,1), 100.0*s/sc, s))
