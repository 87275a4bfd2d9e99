// Marching Cubes (kernels/mc.cl, host/mesh.*): the case table, the device result against the
// float64 host reference, closed sphere meshes with the right area, volume and Euler
// characteristic, PLY output and `softshell mesh`. With SOFTSHELL_GL_TESTS (the GL test binary,
// under Xvfb): the mesh renderer and `render --method mc|shearwarp`.
#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <string>
#include <vector>

#include "cli_fixture.hpp"
#include "error.hpp"
#include "image.hpp"
#include "io.hpp"
#include "mc_tables.h"
#include "mesh.hpp"

#include "test_support.hpp"
#ifdef SOFTSHELL_GL_TESTS
#include "mesh_renderer.hpp"
#endif

namespace softshell {
namespace {

// f = R - |x - c| (mm, positive inside), or the soft shell exp(-(|x - c| - R)^2 / w^2).
Volume sphere_field(Dims3 dims, Vec3d spacing, double radius, bool shell, double width = 2.0) {
  Volume v(dims, spacing);
  v.origin = {-3.0, 2.0, 5.0};
  Vec3d c;
  for (int a = 0; a < 3; ++a) c[a] = v.origin[a] + spacing[a] * 0.5 * double(dims[a] - 1) + 0.21 * spacing[a];
  for (std::size_t z = 0; z < dims[2]; ++z)
    for (std::size_t y = 0; y < dims[1]; ++y)
      for (std::size_t x = 0; x < dims[0]; ++x) {
        const double p[3] = {v.origin[0] + spacing[0] * x - c[0], v.origin[1] + spacing[1] * y - c[1],
                             v.origin[2] + spacing[2] * z - c[2]};
        const double r = std::sqrt(p[0] * p[0] + p[1] * p[1] + p[2] * p[2]);
        v.at(x, y, z) = float(shell ? std::exp(-(r - radius) * (r - radius) / (width * width)) : radius - r);
      }
  return v;
}

}  // namespace

#ifndef SOFTSHELL_GL_TESTS

// ---- The case table: derived again here, compared with kernels/mc_tables.h ----------------------
namespace {
constexpr int kCorner[8][3] = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}, {0, 0, 1}, {1, 0, 1}, {1, 1, 1}, {0, 1, 1}};
constexpr int kEdge[12][2] = {{0, 1}, {1, 2}, {2, 3}, {3, 0}, {4, 5}, {5, 6}, {6, 7}, {7, 4}, {0, 4}, {1, 5}, {2, 6}, {3, 7}};
int edge_of(int a, int b) {
  for (int e = 0; e < 12; ++e)
    if ((kEdge[e][0] == a && kEdge[e][1] == b) || (kEdge[e][0] == b && kEdge[e][1] == a)) return e;
  return -1;
}
// Two cube edges on a common face: all four corners agree in one coordinate.
bool share_face(int e1, int e2) {
  for (int axis = 0; axis < 3; ++axis) {
    const int v = kCorner[kEdge[e1][0]][axis];
    if (kCorner[kEdge[e1][1]][axis] == v && kCorner[kEdge[e2][0]][axis] == v && kCorner[kEdge[e2][1]][axis] == v)
      return true;
  }
  return false;
}
// Triangulates polygon p with no diagonal inside a cell face (first such in a fixed search).
bool split(const std::vector<int>& p, std::vector<std::array<int, 3>>& out) {
  const std::size_t n = p.size();
  if (n < 3) return true;
  if (n == 3) return out.push_back({p[0], p[1], p[2]}), true;
  for (std::size_t k = 2; k < n; ++k) {
    if ((k != 2 && share_face(p[1], p[k])) || (k != n - 1 && share_face(p[k], p[0]))) continue;
    std::vector<std::array<int, 3>> t{{p[0], p[1], p[k]}};
    std::vector<int> a(p.begin() + 1, p.begin() + k + 1), b(p.begin() + k, p.end());
    b.push_back(p[0]);
    if (split(a, t) && split(b, t)) return out.insert(out.end(), t.begin(), t.end()), true;
  }
  return false;
}
// Contour tracing around the six faces (see mc_tables.h): on each face, viewed from outside with
// its corners counter-clockwise, a segment runs from the edge where the boundary leaves the solid
// corners to the edge where it enters them; diagonal solid corners stay separated. The segments
// close into loops, triangulated without diagonals inside a face.
std::vector<std::array<int, 3>> triangulate(int c) {
  int faces[6][4] = {{0, 1, 2, 3}, {4, 5, 6, 7}, {0, 1, 5, 4}, {3, 2, 6, 7}, {0, 3, 7, 4}, {1, 2, 6, 5}};
  int next[12];
  for (int& n : next) n = -1;
  for (auto& f : faces) {
    double out[3] = {-0.5, -0.5, -0.5}, u[3], v[3];
    for (int i = 0; i < 4; ++i)
      for (int a = 0; a < 3; ++a) out[a] += 0.25 * kCorner[f[i]][a];
    for (int a = 0; a < 3; ++a) u[a] = kCorner[f[1]][a] - kCorner[f[0]][a], v[a] = kCorner[f[2]][a] - kCorner[f[1]][a];
    const double n[3] = {u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]};
    if (n[0] * out[0] + n[1] * out[1] + n[2] * out[2] < 0) std::swap(f[1], f[3]);
    bool s[4];
    for (int i = 0; i < 4; ++i) s[i] = (c >> f[i]) & 1;
    int exits[2], entries[2], ne = 0, nn = 0;
    for (int i = 0; i < 4; ++i) {
      if (s[i] && !s[(i + 1) % 4]) exits[ne++] = i;
      if (!s[i] && s[(i + 1) % 4]) entries[nn++] = i;
    }
    auto E = [&](int i) { return edge_of(f[i], f[(i + 1) % 4]); };
    if (ne == 1) next[E(exits[0])] = E(entries[0]);
    if (ne == 2)
      for (int k = 0; k < 2; ++k) next[E(exits[k])] = E((exits[k] + 3) % 4);
  }
  std::vector<std::array<int, 3>> tris;
  bool used[12] = {};
  for (int e0 = 0; e0 < 12; ++e0) {
    if (next[e0] < 0 || used[e0]) continue;
    std::vector<int> loop;
    for (int e = e0; !used[e]; e = next[e]) used[e] = true, loop.push_back(e);
    // the loop winds clockwise seen from the non-solid side: triangulate it reversed
    if (!split(std::vector<int>(loop.rbegin(), loop.rend()), tris)) return {};
  }
  return tris;
}
}  // namespace

TEST(MeshTables, HeaderMatchesTheContourTracing) {
  for (int c = 0; c < 256; ++c) {
    const auto tris = triangulate(c);
    ASSERT_EQ(mc_tri_count[c], tris.size()) << "case " << c;
    ASSERT_EQ(tris.empty(), c == 0 || c == 255) << "case " << c << " has no valid triangulation";
    ASSERT_LE(tris.size(), std::size_t(MC_MAX_TRIANGLES));
    for (std::size_t t = 0; t < tris.size(); ++t)
      for (int k = 0; k < 3; ++k) ASSERT_EQ(mc_tri_table[c][3 * t + k], tris[t][k]) << "case " << c;
    EXPECT_EQ(mc_tri_table[c][3 * tris.size()], -1) << "case " << c;
  }
  // Complementary cases without ambiguous faces give the same surface, reversed.
  EXPECT_EQ(mc_tri_count[1], 1);
  EXPECT_EQ(mc_tri_count[254], 1);
  for (int e = 0; e < 12; ++e) {
    const mc_uchar* p = mc_edge_point[e];
    int a = 0, b = 0;
    for (int k = 0; k < 8; ++k) {
      if (kCorner[k][0] == p[0] && kCorner[k][1] == p[1] && kCorner[k][2] == p[2]) a = k;
      if (kCorner[k][0] == p[0] + (p[3] == 0) && kCorner[k][1] == p[1] + (p[3] == 1) && kCorner[k][2] == p[2] + (p[3] == 2)) b = k;
    }
    EXPECT_EQ(edge_of(a, b), e);
  }
}

// Prints the table body for kernels/mc_tables.h.
TEST(MeshTables, DISABLED_Print) {
  for (int c = 0; c < 256; ++c) {
    std::printf("    {");
    int n = 0;
    for (const auto& t : triangulate(c))
      for (int e : t) std::printf("%d,", e), ++n;
    for (; n < 15; ++n) std::printf("-1,");
    std::printf("-1},\n");
  }
  for (int c = 0; c < 256; ++c) std::printf("%zu,", triangulate(c).size());
  std::printf("\n");
}

// ---- Device against the float64 host reference ----------------------------------------------
TEST(Mesh, MatchesHostReferenceOnRandomFields) {
  Runtime& rt = test::runtime();
  const std::vector<std::pair<Dims3, Vec3d>> shapes = {
      {{7, 9, 5}, {1, 1, 1}}, {{13, 6, 11}, {0.7, 1.3, 2.0}}, {{2, 2, 2}, {1, 1, 1}}, {{17, 3, 9}, {1, 0.5, 1}}};
  std::uint64_t s = test::seed();
  for (const auto& [dims, spacing] : shapes)
    for (double level : {0.5, 0.27}) {
      Volume v = test::random_volume(dims, spacing, s++);
      v.origin = {1.5, -2.0, 0.25};
      SCOPED_TRACE(std::to_string(dims[0]) + "x" + std::to_string(dims[1]) + "x" + std::to_string(dims[2]) +
                   " level " + std::to_string(level));
      const Mesh got = marching_cubes(rt, v, level), want = marching_cubes_reference(v, level);
      ASSERT_EQ(got.triangle_count(), want.triangle_count());
      ASSERT_EQ(got.vertex_count(), want.vertex_count());
      // Same cell order: triangle t is the same triangle in both; compare its corners.
      for (std::size_t i = 0; i < got.triangles.size(); ++i) {
        const std::uint32_t a = got.triangles[i], b = want.triangles[i];
        for (int k = 0; k < 3; ++k) {
          ASSERT_NEAR(got.positions[3 * a + k], want.positions[3 * b + k], 1e-4) << "triangle corner " << i;
          ASSERT_NEAR(got.normals[3 * a + k], want.normals[3 * b + k], 2e-3) << "triangle corner " << i;
        }
      }
    }
}

TEST(Mesh, ClosedOnRandomFieldsWithAZeroBorder) {
  // Every case and face ambiguity occurs; a zero border closes the surface: every edge must be
  // shared by exactly two triangles that traverse it in opposite directions.
  Runtime& rt = test::runtime();
  Volume v = test::random_volume({19, 17, 15}, {1, 1, 1}, test::seed() + 99);
  for (std::size_t z = 0; z < 15; ++z)
    for (std::size_t y = 0; y < 17; ++y)
      for (std::size_t x = 0; x < 19; ++x)
        if (x == 0 || y == 0 || z == 0 || x == 18 || y == 16 || z == 14) v.at(x, y, z) = 0;
  for (double level : {0.3, 0.5, 0.7}) {
    const Mesh m = marching_cubes(rt, v, level);
    const MeshTopology top = mesh_topology(m);
    EXPECT_GT(m.triangle_count(), 500u);
    EXPECT_EQ(top.boundary_edges, 0u) << "level " << level;
    EXPECT_EQ(top.nonmanifold_edges, 0u) << "level " << level;
    EXPECT_EQ(top.misoriented_edges, 0u) << "level " << level;
    EXPECT_EQ(top.degenerate_faces, 0u);
    EXPECT_EQ(top.euler() % 2, 0) << "closed orientable surfaces have even Euler characteristic";
  }
}

// ---- Spheres ------------------------------------------------------------------------------
TEST(Mesh, DistanceFieldSphereIsClosedWithAreaAndVolume) {
  Runtime& rt = test::runtime();
  const double R = 13.0;
  const Volume v = sphere_field({41, 37, 45}, {1.0, 1.1, 0.9}, R, false);
  MeshTiming t;
  const Mesh m = marching_cubes(rt, v, 0.0, &t);
  const MeshTopology top = mesh_topology(m);
  EXPECT_TRUE(top.closed());
  EXPECT_EQ(top.euler(), 2);
  EXPECT_EQ(top.components, 1u);
  const double area = mesh_area(m), volume = mesh_signed_volume(m);
  EXPECT_NEAR(area / (4 * M_PI * R * R), 1.0, 0.02) << area;
  EXPECT_NEAR(volume / (4.0 / 3.0 * M_PI * R * R * R), 1.0, 0.02) << volume;  // > 0: normals point out
  // Normals point out of the solid (towards lower values), along the radius.
  const auto box = m.bounds();
  Vec3d c;
  for (int a = 0; a < 3; ++a) c[a] = 0.5 * (box[0][a] + box[1][a]);
  double worst = 1;
  for (std::size_t i = 0; i < m.vertex_count(); ++i) {
    double d[3], len = 0;
    for (int a = 0; a < 3; ++a) d[a] = m.positions[3 * i + a] - c[a], len += d[a] * d[a];
    len = std::sqrt(len);
    EXPECT_NEAR(len, R, 0.1);
    worst = std::min(worst, (d[0] * m.normals[3 * i] + d[1] * m.normals[3 * i + 1] + d[2] * m.normals[3 * i + 2]) / len);
  }
  EXPECT_GT(worst, 0.995);
}

TEST(Mesh, OpacityShellGivesTwoClosedSpheres) {
  Runtime& rt = test::runtime();
  const double R = 12.0, w = 2.0, level = 0.5;
  const Volume v = sphere_field({39, 39, 39}, {1, 1, 1}, R, true, w);
  const Mesh m = marching_cubes(rt, v, level);
  const MeshTopology top = mesh_topology(m);
  EXPECT_TRUE(top.closed());
  EXPECT_EQ(top.components, 2u);
  EXPECT_EQ(top.euler(), 4);  // two spheres
  const double d = w * std::sqrt(-std::log(level)), r1 = R - d, r2 = R + d;
  EXPECT_NEAR(mesh_area(m) / (4 * M_PI * (r1 * r1 + r2 * r2)), 1.0, 0.03);
  // Normals point out of the shell, so the signed volume is the shell's.
  EXPECT_NEAR(mesh_signed_volume(m) / (4.0 / 3.0 * M_PI * (r2 * r2 * r2 - r1 * r1 * r1)), 1.0, 0.03);
}

TEST(Mesh, DeterministicEmptyAndBadInput) {
  Runtime& rt = test::runtime();
  const Volume v = sphere_field({21, 19, 23}, {1, 1, 1}, 7, true);
  const Mesh a = marching_cubes(rt, v, 0.4), b = marching_cubes(rt, v, 0.4);
  EXPECT_EQ(a.positions, b.positions);
  EXPECT_EQ(a.normals, b.normals);
  EXPECT_EQ(a.triangles, b.triangles);
  EXPECT_TRUE(marching_cubes(rt, v, 2.0).empty());
  EXPECT_TRUE(marching_cubes(rt, v, -1.0).empty());
  EXPECT_THROW(marching_cubes(rt, v, std::nan("")), InputError);
  EXPECT_THROW(marching_cubes(rt, Volume({5, 1, 5}), 0.5), InputError);
}

// ---- PLY ----------------------------------------------------------------------------------
TEST(Mesh, PlyIsBinaryLittleEndianAndReadsBack) {
  Runtime& rt = test::runtime();
  const Mesh m = marching_cubes(rt, sphere_field({15, 15, 15}, {1, 1, 1}, 5, false), 0.0);
  const std::string path = ::testing::TempDir() + "/softshell-mesh-test.ply";
  write_ply_binary(path, m, "test mesh");
  const std::string bytes = test::slurp(path);
  const std::string header = "ply\nformat binary_little_endian 1.0\ncomment test mesh\nelement vertex " +
                             std::to_string(m.vertex_count()) +
                             "\nproperty float x\nproperty float y\nproperty float z\nproperty float nx\n"
                             "property float ny\nproperty float nz\nelement face " +
                             std::to_string(m.triangle_count()) +
                             "\nproperty list uchar int vertex_indices\nend_header\n";
  ASSERT_EQ(bytes.substr(0, header.size()), header);
  EXPECT_EQ(bytes.size(), header.size() + 24 * m.vertex_count() + 13 * m.triangle_count());
  const Mesh r = read_ply_binary(path);
  EXPECT_EQ(r.positions, m.positions);
  EXPECT_EQ(r.normals, m.normals);
  EXPECT_EQ(r.triangles, m.triangles);
  // Truncated: rejected with the file named.
  std::ofstream(path, std::ios::binary | std::ios::trunc) << bytes.substr(0, bytes.size() - 5);
  try {
    read_ply_binary(path);
    FAIL() << "truncated PLY accepted";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find(path), std::string::npos);
  }
  std::remove(path.c_str());
}

// ---- softshell mesh -------------------------------------------------------------------------
class MeshCli : public test::CliTest {};

TEST_F(MeshCli, WritesAClosedSphere) {
  const std::string in = file("sdf.nrrd"), out = file("s.ply");
  write_volume(in, sphere_field({31, 31, 31}, {1, 1, 1}, 10, false));
  const auto r = run({"mesh", in, "--level", "0", "-o", out});
  ASSERT_EQ(r.status, 0) << r.err;
  EXPECT_NE(r.out.find("Euler characteristic 2, closed"), std::string::npos) << r.out;
  const Mesh m = read_ply_binary(out);
  EXPECT_NEAR(mesh_area(m) / (4 * M_PI * 100), 1.0, 0.03);
  EXPECT_NE(run({"mesh", "--help"}).out.find("--level"), std::string::npos);
}

TEST_F(MeshCli, BadInputIsOneLineExitTwo) {
  const std::string in = file("sdf.nrrd");
  write_volume(in, sphere_field({11, 11, 11}, {1, 1, 1}, 3, false));
  expect_one_line_error(run({"mesh", in, "--level", "50", "-o", file("a.ply")}), {"no surface at level 50"});
  expect_one_line_error(run({"mesh", in, "--level", "abc", "-o", file("a.ply")}), {"level"});
  expect_one_line_error(run({"mesh", in, "--level", "nan", "-o", file("a.ply")}), {"level"});
  expect_one_line_error(run({"mesh", in, "-o", file("a.ply")}), {"--level"});
  expect_one_line_error(run({"mesh", in, "--level", "0", "-o", file("a.obj")}), {".ply"});
  expect_one_line_error(run({"mesh", file("missing.nrrd"), "--level", "0", "-o", file("a.ply")}), {"missing.nrrd"});
  write_volume(file("flat.nrrd"), Volume({6, 1, 6}));
  expect_one_line_error(run({"mesh", file("flat.nrrd"), "--level", "0", "-o", file("a.ply")}), {"2 samples"});
  EXPECT_FALSE(test::fs::exists(file("a.ply")));
}

#else  // SOFTSHELL_GL_TESTS

namespace {
double disc_radius_px(const viewer::RgbaImage& img, double* cx, double* cy) {
  double n = 0, sx = 0, sy = 0;
  for (int y = 0; y < img.height; ++y)
    for (int x = 0; x < img.width; ++x)
      if (img.pixel(x, y)[3] > 127) n += 1, sx += x + 0.5, sy += y + 0.5;
  *cx = n > 0 ? sx / n : 0;
  *cy = n > 0 ? sy / n : 0;
  return std::sqrt(n / M_PI);
}
}  // namespace

TEST(MeshRender, SphereSilhouetteMatchesThePerspectiveProjection) {
  test::runtime();
  const double R = 12.0;
  const Volume v = sphere_field({33, 33, 33}, {1, 1, 1}, R, false);
  const Mesh m = marching_cubes(test::runtime(), v, 0.0);
  viewer::OrbitCamera cam;
  const auto box = m.bounds();
  cam.fit(box[0], box[1]);
  for (float az : {0.0f, 50.0f}) {
    cam.azimuth = az;
    cam.elevation = az > 0 ? 20.0f : 0.0f;
    viewer::MeshFrameTiming t;
    const viewer::RgbaImage img = viewer::render_mesh_image(m, cam, viewer::RenderSettings{}, 300, 300, &t);
    double cx, cy;
    const double r = disc_radius_px(img, &cx, &cy);
    const double d = cam.distance;
    const double want = R / std::sqrt(d * d - R * R) / std::tan(glm::radians(0.5 * cam.fov_y)) * 150.0;
    EXPECT_NEAR(r, want, 1.5) << "view " << az;
    // the sphere's centre is 0.21 voxel off the box centre at most: within a pixel or two
    EXPECT_NEAR(cx, 150.0, 2.0);
    EXPECT_NEAR(cy, 150.0, 2.0);
    EXPECT_GT(t.draw, 0.0);
  }
}

class RenderMethodsCli : public test::CliTest {};

TEST_F(RenderMethodsCli, McAndShearWarpWritePngs) {
  const std::string in = file("shell.nrrd");
  write_volume(in, sphere_field({29, 29, 29}, {1, 1, 1}, 9, true));
  for (const char* method : {"mc", "shearwarp"}) {
    SCOPED_TRACE(method);
    const std::string out = file(std::string(method) + ".png");
    const auto r = run({"render", in, "--method", method, "--size", "120x90", "--view", "20,10", "-o", out});
    ASSERT_EQ(r.status, 0) << r.err;
    const Image img = read_png(out);
    EXPECT_EQ(img.width, 120);
    EXPECT_EQ(img.height, 90);
    std::size_t lit = 0;
    for (std::size_t i = 0; i < img.rgb.size(); i += 3) lit += img.rgb[i] > 20;
    EXPECT_GT(lit, 1000u);
  }
  expect_one_line_error(run({"render", in, "--method", "mc", "--level", "3", "-o", file("x.png")}),
                        {"no surface at level 3"});
  expect_one_line_error(run({"render", in, "--method", "shearwarp", "--turntable", "4", "-o", file("x.png")}),
                        {"--turntable"});
  EXPECT_FALSE(test::fs::exists(file("x.png")));
}

#endif  // SOFTSHELL_GL_TESTS

}  // namespace softshell
