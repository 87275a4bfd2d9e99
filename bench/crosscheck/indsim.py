#!/usr/bin/env python3
"""An independent 3D ultrasound simulator for cross-checking softshell's defaults
(docs/crosscheck.md).

Written apart from softshell's phantom (host/phantom*.cpp), sharing no code or
constants with it: other anatomy (posed at random),
other scattering statistics (sparse scatterers: partly developed, K-like speckle), specular
echoes from the impedance gradient along the beam (|n.b|, not |n.b|^3), an asymmetric axial
pulse, lateral side lobes, a depth-varying lateral PSF (focus), a TGC that does not match the
attenuation, a scanner's S-shaped grey map, auto gain on a percentile, and uint8, uint16 or
float output. A fan (40 %) is formed along its beams (a curvilinear probe: the image in beam
space, then scan-converted), so its shadows and near-field layers follow the beams.

Needs python3-numpy and python3-scipy (Debian). Not used by the tests.

usage: indsim.py head|bone|cyst SEED OUTDIR
writes OUTDIR/volume.nrrd, truth_sdf.nrrd (units of the smallest spacing, < 0 inside),
shadow_db.nrrd (two-way loss from interfaces and bone, dB), sim.json
"""
import sys, os, json, numpy as np
from scipy import ndimage, fft

shape, seed, out = sys.argv[1], int(sys.argv[2]), sys.argv[3]
os.makedirs(out, exist_ok=True)
rng = np.random.default_rng(seed * 7919 + {'head': 1, 'bone': 2, 'cyst': 3}[shape])
U = rng.uniform

# ---------------------------------------------------------------- grid
n_lat = int(rng.choice([80, 96, 112]))
n_ax = int(rng.choice([80, 96, 112]))
fov_lat = {'head': U(70, 110), 'bone': U(45, 75), 'cyst': U(40, 70)}[shape]
h_lat = fov_lat / n_lat
depth = {'head': U(70, 110), 'bone': U(45, 80), 'cyst': U(40, 70)}[shape]
h_ax = depth / n_ax
nx, ny, nz = n_lat, int(n_lat * U(0.8, 1.0)), n_ax
hx, hy, hz = h_lat, h_lat * U(0.9, 1.3), h_ax
hmin = min(hx, hy, hz)
z = (np.arange(nz) + 0.5)[:, None, None] * hz
y = ((np.arange(ny) + 0.5) - ny / 2)[None, :, None] * hy
x = ((np.arange(nx) + 0.5) - nx / 2)[None, None, :] * hx
Z, Y, X = np.broadcast_arrays(z, y, x)
P = np.stack([X, Y, Z], -1).astype(np.float64)   # [z,y,x,3] mm

# fan (sector) geometry, from its own random stream (a linear case draws everything else as
# before): a curvilinear probe of radius R whose beams run from the apex (x 0, z -R); the image
# is formed along those beams (attenuation, shadows, specular echoes, the pulse and the lateral
# PSF in beam space, then scan-converted), and is zero outside the sector and above the probe's
# arc. D: depth under the probe (along the beam in a fan), for the layers under it.
frng = np.random.default_rng([seed, {'head': 1, 'bone': 2, 'cyst': 3}[shape], 17])
fan = frng.uniform() < 0.4
if fan:
    R_probe = frng.uniform(5, 30)
    half = frng.uniform(0.35, 0.6)
    Rr = np.hypot(X, Z + R_probe)
    D = Rr - R_probe
else:
    D = Z


def rot(yaw, pitch, roll):
    cy, sy, cp, sp, cr, sr = np.cos(yaw), np.sin(yaw), np.cos(pitch), np.sin(pitch), np.cos(roll), np.sin(roll)
    Rz = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]])
    Rx = np.array([[1, 0, 0], [0, cp, -sp], [0, sp, cp]])
    Ry = np.array([[cr, 0, sr], [0, 1, 0], [-sr, 0, cr]])
    return Rz @ Rx @ Ry


def sd_sphere(p, c, r):
    return np.linalg.norm(p - c, axis=-1) - r


def sd_capsule(p, a, b, r):
    a, b = np.asarray(a, float), np.asarray(b, float)
    pa, ba = p - a, b - a
    h = np.clip((pa @ ba) / (ba @ ba), 0, 1)
    return np.linalg.norm(pa - h[..., None] * ba, axis=-1) - r


def sd_ellipsoid(p, c, R, rad):
    q = (p - c) @ R            # into the body frame
    rad = np.asarray(rad, float)
    k0 = np.linalg.norm(q / rad, axis=-1)
    k1 = np.linalg.norm(q / rad**2, axis=-1)
    return k0 * (k0 - 1) / np.maximum(k1, 1e-9)


def sd_box(p, c, R, half, r=0.0):
    q = np.abs((p - c) @ R) - (np.asarray(half, float) - r)
    return np.linalg.norm(np.maximum(q, 0), axis=-1) + np.minimum(q.max(-1), 0) - r


def smin(a, b, k):
    h = np.maximum(k - np.abs(a - b), 0) / k
    return np.minimum(a, b) - h * h * k / 4


def texture(scale_mm, amp, aniso=(1, 1, 1)):
    g = rng.standard_normal((nz, ny, nx))
    s = [scale_mm * aniso[2] / hz, scale_mm * aniso[1] / hy, scale_mm * aniso[0] / hx]
    g = ndimage.gaussian_filter(g, s, mode='wrap')
    g /= g.std() + 1e-12
    return np.exp(amp * g - amp**2 / 2)


# ---------------------------------------------------------------- anatomy
# label: 0 fluid (anechoic), 1 soft tissue, 2 bone, 3 skin/fat layers (near field), 4 wall
# truth: the surfaces a user wants (fluid/tissue for head and cyst; bone for bone)
params = {'shape': shape, 'seed': seed, 'dims': [nx, ny, nz], 'spacing': [hx, hy, hz]}
scatter = np.zeros((nz, ny, nx))       # mean backscatter power
atten = np.zeros((nz, ny, nx))         # dB / mm, one way
imped = np.zeros((nz, ny, nx))         # acoustic impedance (arbitrary units)
bone_mask = np.zeros((nz, ny, nx), bool)

if shape == 'head':
    R = rot(U(-0.6, 0.6), U(-0.5, 0.5), U(-0.4, 0.4))
    a = U(0.2, 0.28) * fov_lat
    rad = np.array([a * U(0.85, 1.0), a * U(1.0, 1.15), a * U(0.9, 1.05)])
    c = np.array([U(-0.1, 0.1) * fov_lat, U(-0.1, 0.1) * fov_lat, depth * U(0.5, 0.6)])
    head = sd_ellipsoid(P, c, R, rad)
    f = R @ np.array([0, 0, -1.0])       # the face's direction (toward the probe before posing)
    up = R @ np.array([0, -1.0, 0])
    nose_base = c + f * rad[2] * 0.92
    nose = sd_capsule(P, nose_base - f * 2, nose_base + f * U(4, 7) + up * U(-2, 0), U(2.5, 4))
    brow = sd_capsule(P, c + f * rad[2] * 0.75 + up * rad[1] * 0.45 - R @ np.array([rad[0] * 0.5, 0, 0]),
                      c + f * rad[2] * 0.75 + up * rad[1] * 0.45 + R @ np.array([rad[0] * 0.5, 0, 0]), U(3, 5))
    chin = sd_sphere(P, c + f * rad[2] * 0.75 - up * rad[1] * 0.75, U(5, 8))
    body = sd_capsule(P, c - up * rad[1] * 0.9 + f * 3, c - up * rad[1] * 3.5 + f * U(0, 10), rad[0] * 0.75)
    obj = smin(smin(smin(smin(head, nose, 3), brow, 3), chin, 4), body, 6)
    parts = [obj]
    if rng.uniform() < 0.6:              # a limb between the probe and the face
        p0 = np.array([U(-1, 1) * fov_lat * 0.6, U(-1, 1) * fov_lat * 0.6, c[2] - rad[2] - U(6, 14)])
        d = rng.standard_normal(3); d[2] *= 0.3; d /= np.linalg.norm(d)
        parts.append(sd_capsule(P, p0 - d * U(10, 30), p0 + d * U(10, 30), U(3, 6)))
    if rng.uniform() < 0.5:              # an umbilical cord: a wavy tube
        t = np.linspace(-1, 1, 14)
        base = np.array([U(-0.4, 0.4) * fov_lat, U(-0.4, 0.4) * fov_lat, U(0.15, 0.35) * depth])
        d = rng.standard_normal(3); d[2] *= 0.3; d /= np.linalg.norm(d)
        w = rng.standard_normal(3) * 6
        pts = [base + d * ti * fov_lat * 0.6 + w * np.sin(3 * ti + U(0, 6)) for ti in t]
        rc = U(3, 5)
        cord = np.min([sd_capsule(P, pts[i], pts[i + 1], rc) for i in range(len(pts) - 1)], axis=0)
        parts.append(cord)
    wall_z = depth * U(0.82, 0.95) + 0.08 * depth * np.sin(X / U(10, 30) + U(0, 6)) * U(0, 1)
    wall = wall_z - Z                    # < 0 below the wall's top
    tissue_sdf = np.min(parts + [wall], axis=0)
    truth = tissue_sdf
    inside = tissue_sdf < 0
    skull = (head > -U(4, 6)) & (head < -U(1.5, 2.5)) & (head < 0)
    tex = texture(U(2, 5), U(0.2, 0.5))
    scatter[:] = 0.0005
    scatter[inside] = tex[inside]
    scatter[wall < 0] *= U(1.0, 2.0)
    scatter[skull] = U(5, 15)
    atten[:] = 0.0002 * 3.5
    atten[inside] = U(0.04, 0.09)
    atten[skull] = U(0.8, 1.5)
    imped[:] = 1.50
    imped[inside] = U(1.58, 1.68)
    imped[skull] = U(3.5, 6)
    bone_mask = skull
    near = U(0, 1) < 0.7
elif shape == 'bone':
    # skin, fat, muscle, then lumbar-like vertebrae posed at random
    R = rot(U(-0.8, 0.8), U(-0.25, 0.25), U(-0.25, 0.25))
    nvert = int(rng.integers(2, 5))
    spacing_v = U(0.28, 0.4) * fov_lat
    base_depth = depth * U(0.45, 0.6)
    parts = []
    for k in range(nvert):
        cx = (k - (nvert - 1) / 2) * spacing_v
        s = U(0.85, 1.15) * fov_lat / 60
        c = R @ np.array([cx, 0, 0]) + np.array([0, 0, base_depth])
        # spinous process: toward the probe
        tip = c + R @ np.array([U(-2, 2), 0, -U(10, 16) * s])
        parts.append(sd_capsule(P, c + R @ np.array([0, 0, -3 * s]), tip, U(1.8, 2.8) * s))
        # laminae: plates either side, sloping down
        for side in (-1, 1):
            Rl = R @ rot(0, 0, side * U(0.25, 0.5))
            lam = sd_box(P, c + R @ np.array([0, side * 7 * s, -1 * s]), Rl, [U(4, 6) * s, 5 * s, 1.5 * s], 1.0)
            parts.append(lam)
            tp = sd_capsule(P, c + R @ np.array([0, side * 9 * s, 3 * s]),
                            c + R @ np.array([U(-2, 2), side * U(18, 24) * s, U(3, 7) * s]), U(1.5, 2.2) * s)
            parts.append(tp)
        # the vertebral body, deep
        parts.append(sd_box(P, c + R @ np.array([0, 0, 14 * s]), R, [5 * s, 8 * s, 6 * s], 2.0))
    bone = parts[0]
    for q in parts[1:]:
        bone = smin(bone, q, 1.2)
    truth = bone
    inside = bone < 0
    skin = U(1.5, 3)
    fat = skin + U(2, 8)
    tex = texture(U(2, 4), U(0.3, 0.6), aniso=(3, 1, 1))   # fibres
    scatter[:] = tex * U(0.6, 1.2)
    scatter[D < skin] = U(2, 5)
    fatz = (D >= skin) & (D < fat)
    scatter[fatz] = U(0.15, 0.5) * texture(1.5, 0.6)[fatz]
    fascia = np.abs(D - fat) < 0.6
    scatter[fascia] = U(3, 8)
    scatter[inside] = U(2, 6)
    atten[:] = U(0.06, 0.12)
    atten[fatz] = U(0.04, 0.08)
    atten[inside] = U(2, 5)
    imped[:] = 1.66
    imped[fatz] = 1.38
    imped[inside] = U(5, 7.5)
    bone_mask = inside
    near = True
else:  # cyst: anechoic lesions in parenchyma, posterior enhancement
    parts = []
    for k in range(int(rng.integers(2, 6))):
        c = np.array([U(-0.35, 0.35) * fov_lat, U(-0.3, 0.3) * fov_lat, U(0.3, 0.8) * depth])
        rad = np.array([U(3, 10), U(3, 10), U(3, 9)])
        parts.append(sd_ellipsoid(P, c, rot(U(0, 6), U(-1, 1), U(-1, 1)), rad))
    cyst = np.min(parts, axis=0)
    truth = -cyst                        # tissue inside the truth: outside the cysts
    inside = cyst < 0
    tex = texture(U(1.5, 4), U(0.15, 0.4))
    scatter[:] = tex
    scatter[inside] = 0.0005
    atten[:] = U(0.05, 0.1)
    atten[inside] = 0.001
    imped[:] = 1.65
    imped[inside] = 1.52
    near = U(0, 1) < 0.8

if shape != 'bone' and near:                 # skin and fat under the probe
    skin = U(1, 3); fat = skin + U(1, 6)
    sel = D < skin
    scatter[sel] = U(2, 6); atten[sel] = 0.1; imped[sel] = 1.7
    if shape == 'head':                  # the abdominal wall, over fluid
        sel = (D >= skin) & (D < fat)
        scatter[sel] = U(0.2, 0.6); atten[sel] = 0.06; imped[sel] = 1.4
        m = (D >= fat) & (D < fat + U(3, 8))
        scatter[m] = U(0.8, 1.5) * texture(2, 0.4)[m]; atten[m] = 0.1; imped[m] = 1.66
        params['near_field_mm'] = float(fat)
truth_vox = truth / hmin

# ---------------------------------------------------------------- image formation
f_mhz = U(2.5, 7.0)
lam = 1.54 / f_mhz
ax_sigma = U(0.5, 1.2) * lam           # pulse envelope (mm)
lat_focus_sigma = U(0.35, 0.7) * lam * 4
focus_depth = U(0.3, 0.7) * depth
side_lobe = 10 ** (-U(20, 32) / 20)    # amplitude of the lateral side lobes
density = np.exp(U(np.log(0.3), np.log(8)))   # scatterers per voxel
params.update(f_mhz=f_mhz, ax_sigma_mm=ax_sigma, lat_sigma_mm=lat_focus_sigma, focus_mm=focus_depth,
              side_lobe_db=float(20 * np.log10(side_lobe)), scatterers_per_voxel=density)

def form(scatter, atten, imped, bone_mask, Zb, hz, hy, hx):
    """The image along the beams (axis 0), lateral across axes 1 and 2: the envelope and the
    two-way loss from interfaces and bone (dB). Zb: depth under the probe (mm)."""
    nz, ny, nx = scatter.shape
    Z = Zb
    # sparse scatterers: a Poisson count per voxel, each with a random phase and unit amplitude
    cnt = rng.poisson(density, size=(nz, ny, nx))
    ph_r = rng.standard_normal((nz, ny, nx)) * np.sqrt(cnt / 2)
    ph_i = rng.standard_normal((nz, ny, nx)) * np.sqrt(cnt / 2)
    amp = np.sqrt(scatter / density) * (ph_r + 1j * ph_i)

    # specular echoes: the impedance's change along the beam (signed, coherent)
    Zs = ndimage.gaussian_filter(imped, [0.3 / hz * 1, 0.5 / hy, 0.5 / hx])
    dZ = np.gradient(Zs, hz, axis=0) * hz
    refl = dZ / (2 * Zs)
    spec_gain = U(3, 12)
    amp = amp + spec_gain * refl * np.exp(1j * U(0, 6.28))

    # attenuation and transmission along +z (two way), shadow_db for the evaluation
    loss_att = 2 * np.cumsum(atten * hz, axis=0) - atten * hz
    T = np.clip(1 - refl**2 * 1.0, 1e-6, 1)
    loss_tr = -2 * 10 * np.log10(np.cumprod(T, axis=0))
    extra_bone = 2 * np.cumsum(np.where(bone_mask, atten, 0) * hz, axis=0)
    shadow_db = (loss_tr + extra_bone).astype(np.float32)
    loss = loss_att + loss_tr
    amp = amp * 10 ** (-loss / 20)

    # PSF: asymmetric axial pulse (fast rise, slow ring-down), lateral Gaussian whose width grows away
    # from the focus, plus side lobes (a wider, weaker Gaussian)
    # The kernel symmetric in extent, kz = 0 at its middle sample: convolve1d centres a kernel at
    # len // 2, and the first version's kernel (4 sigma before, 6 after) put the pulse's peak 1-2
    # samples toward the probe from its interface (version 3, docs/crosscheck.md).
    nk = int(6 * ax_sigma / hz) + 1
    kz = np.arange(-nk, nk + 1) * hz
    assert kz[len(kz) // 2] == 0, 'the pulse must be centred where convolve1d puts the origin'
    pulse = np.where(kz < 0, np.exp(-kz**2 / (2 * (0.6 * ax_sigma)**2)), np.exp(-kz**2 / (2 * (1.5 * ax_sigma)**2)))
    pulse = pulse * np.exp(1j * 2 * np.pi * kz / lam * 0.15)   # residual phase across the pulse
    amp = ndimage.convolve1d(amp.real, pulse.real, axis=0, mode='nearest') - ndimage.convolve1d(amp.imag, pulse.imag, axis=0, mode='nearest') \
        + 1j * (ndimage.convolve1d(amp.real, pulse.imag, axis=0, mode='nearest') + ndimage.convolve1d(amp.imag, pulse.real, axis=0, mode='nearest'))
    out_a = np.zeros_like(amp)
    depth_levels = [0.0, 0.5, 1.0]
    for lv in depth_levels:
        zc = focus_depth + (lv * 2 - 1) * depth * 0.5 if lv != 0.5 else focus_depth
        dz = np.abs(zc - focus_depth)
        sig = lat_focus_sigma * (1 + (dz / (0.35 * depth))**2) ** 0.5
        main = ndimage.gaussian_filter(amp.real, [0, sig / hy, sig / hx]) + 1j * ndimage.gaussian_filter(amp.imag, [0, sig / hy, sig / hx])
        sl = ndimage.gaussian_filter(amp.real, [0, 4 * sig / hy, 4 * sig / hx]) + 1j * ndimage.gaussian_filter(amp.imag, [0, 4 * sig / hy, 4 * sig / hx])
        img = main + side_lobe * 16 * sl
        # blend weights: hat functions over depth
        w = np.clip(1 - np.abs(Z[:, :1, :1] - zc) / (0.5 * depth), 0, 1)
        out_a += w * img
    wsum = sum(np.clip(1 - np.abs(Z[:, :1, :1] - (focus_depth + (lv * 2 - 1) * depth * 0.5 if lv != 0.5 else focus_depth)) / (0.5 * depth), 0, 1) for lv in depth_levels)
    amp = out_a / np.maximum(wsum, 1e-6)

    # TGC that does not match the attenuation, then noise, envelope, log compression, grey map
    tgc_slope = 2 * float(np.median(atten)) * U(0.5, 1.3)
    tgc = tgc_slope * Z + U(-3, 3) * np.sin(Z / depth * U(2, 6))
    amp = amp * 10 ** (tgc / 20) * 10 ** (U(-10, 10) / 20)
    noise = 10 ** (-U(35, 55) / 20)
    amp = amp + noise * (rng.standard_normal(amp.shape) + 1j * rng.standard_normal(amp.shape)) / np.sqrt(2)
    env = np.abs(amp)
    return env, shadow_db, tgc_slope


if fan:
    # beam space: r from the probe's arc to the volume's deepest corner, angle across the sector
    r_max = float(np.hypot(np.abs(x).max() + hx, z.max() + hz + R_probe))
    nr = int(np.ceil((r_max - R_probe) / hz)) + 1
    dth = hx / (R_probe + 0.5 * (r_max - R_probe))
    nth = int(np.ceil(2 * half / dth)) + 1
    rb = R_probe + np.arange(nr)[:, None, None] * hz
    thb = (-half + np.arange(nth) * dth)[None, None, :]
    xb = rb * np.sin(thb); zb = rb * np.cos(thb) - R_probe
    cz = np.broadcast_to(zb / hz - 0.5, (nr, ny, nth)); cx = np.broadcast_to(xb / hx + nx / 2 - 0.5, (nr, ny, nth))
    cy = np.broadcast_to(np.arange(ny)[None, :, None].astype(float), (nr, ny, nth))
    coords = np.stack([cz, cy, cx])
    to_beams = lambda a, o: ndimage.map_coordinates(a.astype(np.float64), coords, order=o, mode='nearest')
    env_b, shadow_b, tgc_slope = form(to_beams(scatter, 1), to_beams(atten, 1), to_beams(imped, 1),
                                      to_beams(bone_mask.astype(float), 0) > 0.5,
                                      np.broadcast_to(rb - R_probe, (nr, ny, nth)), hz, hy, hx)
    # scan conversion: each voxel from its beam (linear in r and angle)
    ang = np.arctan2(X, Z + R_probe)
    back = np.stack([(Rr - R_probe) / hz, np.broadcast_to(np.arange(ny)[None, :, None].astype(float), X.shape),
                     (ang + half) / dth])
    env = ndimage.map_coordinates(env_b, back, order=1, mode='nearest')
    shadow_db = ndimage.map_coordinates(shadow_b, back, order=1, mode='nearest').astype(np.float32)
    outside = (np.abs(ang) > half) | (Rr < R_probe)
else:
    env, shadow_db, tgc_slope = form(scatter, atten, imped, bone_mask, Z, hz, hy, hx)
    outside = np.zeros(Z.shape, bool)
db = 20 * np.log10(env + 1e-12)
dr = U(30, 60)
top = np.percentile(db, U(99.0, 99.9))
g = np.clip((db - (top - dr)) / dr, 0, 1)
k = U(0, 1.5)                            # an S-shaped grey map
g = g + k * 0.08 * np.sin(2 * np.pi * g) * -1
g = np.clip(g, 0, 1) ** U(0.8, 1.3)
params.update(dynamic_range_db=dr, tgc_db_per_mm=tgc_slope, grey_map_k=k)

# fan: zeros outside the sector, as a scan converter leaves them (the draws that once chose the
# fan here are kept, so that a linear case draws its output type as before)
if rng.uniform() < 0.4:
    U(5, 30), U(0.35, 0.6)
if fan:
    g[outside] = 0
    shadow_db[outside] = 1000.0  # never scanned: not visible (recall_visible leaves it out)
    params['fan'] = [-R_probe, half]

otype = rng.choice(['uint8', 'uint8', 'uint16', 'float'])
if otype == 'uint8':
    vol = np.round(g * 255).astype(np.uint8)
elif otype == 'uint16':
    vol = np.round(g * U(3000, 60000)).astype(np.uint16)
else:
    scale = U(0.5, 100)
    vol = (g * scale + U(-0.2, 0.2) * scale).astype(np.float32)
    vol[outside] = 0
params['type'] = str(otype)


def write(fn, a, typ):
    hdr = ('NRRD0004\ntype: %s\ndimension: 3\nspace: left-posterior-superior\nsizes: %d %d %d\n'
           'space directions: (%r,0,0) (0,%r,0) (0,0,%r)\ncenterings: cell cell cell\nkinds: space space space\n'
           'endian: little\nencoding: raw\nspace origin: (0,0,0)\n\n') % (typ, nx, ny, nz, hx, hy, hz)
    with open(fn, 'wb') as f:
        f.write(hdr.encode()); f.write(np.ascontiguousarray(a).tobytes())


write(out + '/volume.nrrd', vol, {'uint8': 'uchar', 'uint16': 'ushort', 'float': 'float'}[str(otype)])
write(out + '/truth_sdf.nrrd', truth_vox.astype(np.float32), 'float')
write(out + '/shadow_db.nrrd', shadow_db, 'float')
json.dump({k: (float(v) if isinstance(v, (np.floating,)) else v) for k, v in params.items()}, open(out + '/sim.json', 'w'), indent=1, default=float)
print(shape, seed, 'dims', nx, ny, nz, 'spacing %.3f %.3f %.3f' % (hx, hy, hz), otype, 'dr %.0f' % dr, 'density %.2f' % density)
