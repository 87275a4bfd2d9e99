# Where a shell lies against a phantom's truth (docs/parameters.md,
# "Clipped echoes"): for each opacity volume, a row of two middle slices
# (coronal y = ny/2 and sagittal x = nx/2, depth down) of the B-mode data in
# grey, the opacity in green and the true surface (|sdf| < 0.6 voxels) in red
# (white where both), scaled 3x; and on stdout the quartiles of the true
# signed distance (voxels, > 0 outside the object) over the drawn voxels
# (u > 0.2) within 6 voxels of the surface: a shell outside the object reads
# positive.
#
#   python3 bench/phantom_overlay.py PHANTOM_DIR U.nrrd [U2.nrrd ...] -o OUT.png
#
# PHANTOM_DIR is `softshell phantom -o DIR` (volume.nrrd, truth_sdf.nrrd;
# raw uint8 and float NRRDs, as softshell writes them). No dependencies.
import array, struct, sys, zlib


def read_nrrd(path):
    data = open(path, 'rb').read()
    end = data.index(b'\n\n')
    header = data[:end].decode()
    fields = dict(line.split(':', 1) for line in header.split('\n')[1:] if ':' in line and not line.startswith('#'))
    if fields.get('encoding', 'raw').strip() != 'raw':
        sys.exit('phantom_overlay: %s: only raw NRRD encoding is read' % path)
    kind = fields['type'].strip()
    values = array.array('B' if kind in ('unsigned char', 'uchar', 'uint8') else 'f')
    dims = [int(t) for t in fields['sizes'].split()]
    values.frombytes(data[end + 2:end + 2 + dims[0] * dims[1] * dims[2] * values.itemsize])
    return values, dims


def write_png(path, width, height, rgb):
    rows = b''.join(b'\x00' + bytes(rgb[y * width * 3:(y + 1) * width * 3]) for y in range(height))
    def chunk(tag, body):
        return struct.pack('>I', len(body)) + tag + body + struct.pack('>I', zlib.crc32(tag + body) & 0xffffffff)
    open(path, 'wb').write(b'\x89PNG\r\n\x1a\n' + chunk(b'IHDR', struct.pack('>IIBBBBB', width, height, 8, 2, 0, 0, 0)) +
                           chunk(b'IDAT', zlib.compress(rows)) + chunk(b'IEND', b''))


def main(argv):
    if '-o' not in argv or len(argv) < 4:
        sys.exit(__doc__ or 'usage: phantom_overlay.py PHANTOM_DIR U.nrrd [U2.nrrd ...] -o OUT.png')
    out = argv[argv.index('-o') + 1]
    args = [a for i, a in enumerate(argv) if a != '-o' and (i == 0 or argv[i - 1] != '-o')]
    phantom, opacities = args[0], args[1:]
    v, dims = read_nrrd(phantom + '/volume.nrrd')
    sdf, _ = read_nrrd(phantom + '/truth_sdf.nrrd')
    nx, ny, nz = dims
    scale, gap = 3, 4
    width = (nx + ny) * scale + gap
    height = len(opacities) * (nz * scale + gap)
    rgb = bytearray(width * height * 3)
    for row, path in enumerate(opacities):
        u, udims = read_nrrd(path)
        if udims != dims:
            sys.exit('phantom_overlay: %s has dims %s, the phantom %s' % (path, udims, dims))
        near = sorted(sdf[i] for i in range(len(u)) if u[i] > 0.2 and abs(sdf[i]) < 6)
        if near:
            q = lambda f: near[int(f * (len(near) - 1))]
            print('%s: %d drawn voxels near the surface, signed distance q25 %.2f median %.2f q75 %.2f voxels'
                  % (path, len(near), q(0.25), q(0.5), q(0.75)))
        x0 = 0
        for across, fixed, count in (('x', ny // 2, nx), ('y', nx // 2, ny)):
            for z in range(nz):
                for a in range(count):
                    i = (a + nx * (fixed + ny * z)) if across == 'x' else (fixed + nx * (a + ny * z))
                    grey = 0.6 * v[i]
                    r = g = b = grey
                    if u[i] > 0.05:
                        g = min(255.0, grey + 255 * u[i])
                        r = b = grey * (1 - u[i])
                    if abs(sdf[i]) < 0.6:
                        drawn = u[i] > 0.2
                        r, g, b = 255, (g if drawn else 0), (255 if drawn else 0)
                    pixel = bytes((int(r), int(g), int(b)))
                    for dy in range(scale):
                        y = row * (nz * scale + gap) + z * scale + dy
                        for dx in range(scale):
                            o = (y * width + x0 + a * scale + dx) * 3
                            rgb[o:o + 3] = pixel
            x0 += count * scale + gap
    write_png(out, width, height, rgb)


if __name__ == '__main__':
    main(sys.argv[1:])
