// Host wrapper of kernels/mc.cl, the float64 host reference, PLY I/O and mesh measures.
#include "mesh.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <map>
#include <numeric>
#include <unordered_map>

#include "error.hpp"
#include "io.hpp"
#include "mc_tables.h"

namespace softshell {
namespace {

using Clock = std::chrono::steady_clock;
double since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

void check_input(const Volume& v, double level) {
  if (!std::isfinite(level)) throw InputError("level must be a finite number");
  for (int a = 0; a < 3; ++a)
    if (v.dims[a] < 2)
      throw InputError("Marching Cubes needs at least 2 samples along every axis (dims " +
                       std::to_string(v.dims[0]) + "x" + std::to_string(v.dims[1]) + "x" +
                       std::to_string(v.dims[2]) + ")");
  if (v.voxels() > 0xffffffffull / 4) throw InputError("volume too large for Marching Cubes (32-bit indices)");
}

}  // namespace

std::array<Vec3d, 2> Mesh::bounds() const {
  std::array<Vec3d, 2> b{Vec3d{0, 0, 0}, Vec3d{0, 0, 0}};
  if (positions.empty()) return b;
  for (int a = 0; a < 3; ++a) b[0][a] = b[1][a] = positions[a];
  for (std::size_t i = 0; i < positions.size(); i += 3)
    for (int a = 0; a < 3; ++a) {
      b[0][a] = std::min(b[0][a], double(positions[i + a]));
      b[1][a] = std::max(b[1][a], double(positions[i + a]));
    }
  return b;
}

std::size_t Mesh::memory_bytes() const {
  return (positions.size() + normals.size()) * sizeof(float) + triangles.size() * sizeof(std::uint32_t);
}

Mesh marching_cubes(Runtime& rt, const Volume& v, double level, MeshTiming* timing) {
  check_input(v, level);
  const auto t0 = Clock::now();
  const GridDesc g = make_grid(v.dims, v.spacing);
  const std::size_t n = v.voxels();
  const float lv = static_cast<float>(level);

  cl::Buffer f = rt.buffer(n * sizeof(float), CL_MEM_READ_ONLY);
  cl::Buffer mask_b = rt.buffer(n), cases_b = rt.buffer(n);
  rt.queue().enqueueWriteBuffer(f, CL_FALSE, 0, n * sizeof(float), v.data.data());
  cl::Kernel classify = rt.kernel("mc.cl", "mc_classify");
  Runtime::set_args(classify, f, mask_b, cases_b, g, lv);
  cl::Event ec = rt.enqueue_3d(classify, g);

  // Exclusive scans on the host, in voxel order (deterministic; the totals size the output).
  const auto ts = Clock::now();
  std::vector<std::uint8_t> mask(n), cases(n);
  rt.queue().enqueueReadBuffer(mask_b, CL_FALSE, 0, n, mask.data());
  rt.queue().enqueueReadBuffer(cases_b, CL_TRUE, 0, n, cases.data());
  std::vector<cl_uint> voff(n), toff(n);
  std::uint64_t nv = 0, nt = 0;
  for (std::size_t i = 0; i < n; ++i) {
    voff[i] = cl_uint(nv);
    toff[i] = cl_uint(nt);
    nv += (mask[i] & 1) + ((mask[i] >> 1) & 1) + ((mask[i] >> 2) & 1);
    nt += mc_tri_count[cases[i]];
  }
  if (nv > 0xffffffffull || 3 * nt > 0xffffffffull) throw DeviceError("mesh too large for 32-bit indices");

  Mesh mesh;
  if (timing) {
    timing->classify = event_seconds(ec);
    timing->scan = since(ts);
  }
  if (nt == 0) {
    if (timing) timing->total = since(t0);
    return mesh;
  }
  cl::Buffer voff_b = rt.buffer(n * sizeof(cl_uint), CL_MEM_READ_ONLY);
  cl::Buffer toff_b = rt.buffer(n * sizeof(cl_uint), CL_MEM_READ_ONLY);
  rt.queue().enqueueWriteBuffer(voff_b, CL_FALSE, 0, n * sizeof(cl_uint), voff.data());
  rt.queue().enqueueWriteBuffer(toff_b, CL_FALSE, 0, n * sizeof(cl_uint), toff.data());
  if (timing) timing->scan = since(ts);

  cl::Buffer pos_b = rt.buffer(nv * 3 * sizeof(float)), nrm_b = rt.buffer(nv * 3 * sizeof(float));
  cl::Buffer tri_b = rt.buffer(nt * 3 * sizeof(cl_uint));
  const cl_float4 org{{float(v.origin[0]), float(v.origin[1]), float(v.origin[2]), 0.0f}};
  cl::Kernel vertices = rt.kernel("mc.cl", "mc_vertices");
  Runtime::set_args(vertices, f, mask_b, voff_b, g, lv, org, pos_b, nrm_b);
  cl::Event ev = rt.enqueue_3d(vertices, g);
  cl::Kernel triangles = rt.kernel("mc.cl", "mc_triangles");
  Runtime::set_args(triangles, cases_b, mask_b, voff_b, toff_b, g, tri_b);
  cl::Event et = rt.enqueue_3d(triangles, g);

  const auto tr = Clock::now();
  mesh.positions.resize(nv * 3);
  mesh.normals.resize(nv * 3);
  mesh.triangles.resize(nt * 3);
  rt.queue().enqueueReadBuffer(pos_b, CL_FALSE, 0, nv * 3 * sizeof(float), mesh.positions.data());
  rt.queue().enqueueReadBuffer(nrm_b, CL_FALSE, 0, nv * 3 * sizeof(float), mesh.normals.data());
  rt.queue().enqueueReadBuffer(tri_b, CL_TRUE, 0, nt * 3 * sizeof(cl_uint), mesh.triangles.data());
  if (timing) {
    timing->generate = event_span_seconds(ev, et);
    timing->read = since(tr);
    timing->total = since(t0);
  }
  return mesh;
}

Mesh marching_cubes_reference(const Volume& v, double level) {
  check_input(v, level);
  const std::size_t nx = v.dims[0], ny = v.dims[1], nz = v.dims[2];
  auto solid = [&](std::size_t x, std::size_t y, std::size_t z) { return double(v.at(x, y, z)) > level; };
  auto deriv = [&](std::size_t x, std::size_t y, std::size_t z, int a) {
    std::array<std::size_t, 3> p{x, y, z}, lo = p, hi = p;
    const std::size_t c = p[a], len = v.dims[a];
    double h = v.spacing[a];
    if (c > 0) lo[a] = c - 1;
    if (c + 1 < len) hi[a] = c + 1;
    if (c > 0 && c + 1 < len) h *= 2;
    return (double(v.at(hi[0], hi[1], hi[2])) - double(v.at(lo[0], lo[1], lo[2]))) / h;
  };
  Mesh mesh;
  std::map<std::pair<std::size_t, int>, std::uint32_t> ids;  // (grid point, axis) -> vertex
  auto vertex = [&](std::size_t x, std::size_t y, std::size_t z, int a) {
    const std::size_t key = v.index(x, y, z);
    auto it = ids.find({key, a});
    if (it != ids.end()) return it->second;
    std::array<std::size_t, 3> p{x, y, z}, q = p;
    ++q[a];
    const double fa = v.at(x, y, z), fb = v.at(q[0], q[1], q[2]);
    const double t = std::clamp((level - fa) / (fb - fa), 0.0, 1.0);
    double gr[3], len = 0;
    for (int b = 0; b < 3; ++b) {
      gr[b] = (1 - t) * deriv(p[0], p[1], p[2], b) + t * deriv(q[0], q[1], q[2], b);
      len += gr[b] * gr[b];
    }
    len = std::sqrt(len);
    for (int b = 0; b < 3; ++b) {
      mesh.positions.push_back(float(v.origin[b] + v.spacing[b] * (double(p[b]) + (b == a ? t : 0.0))));
      mesh.normals.push_back(float(len > 0 ? -gr[b] / len : (b == a ? (fb > fa ? -1.0 : 1.0) : 0.0)));
    }
    const auto id = std::uint32_t(ids.size());
    ids[{key, a}] = id;
    return id;
  };
  static const int corner[8][3] = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0},
                                   {0, 0, 1}, {1, 0, 1}, {1, 1, 1}, {0, 1, 1}};
  for (std::size_t z = 0; z + 1 < nz; ++z)
    for (std::size_t y = 0; y + 1 < ny; ++y)
      for (std::size_t x = 0; x + 1 < nx; ++x) {
        int c = 0;
        for (int k = 0; k < 8; ++k)
          if (solid(x + corner[k][0], y + corner[k][1], z + corner[k][2])) c |= 1 << k;
        for (int k = 0; mc_tri_table[c][k] >= 0; ++k) {
          const mc_uchar* e = mc_edge_point[mc_tri_table[c][k]];
          mesh.triangles.push_back(vertex(x + e[0], y + e[1], z + e[2], e[3]));
        }
      }
  return mesh;
}

void mesh_to_world(Mesh& mesh, const Volume& v) {
  if (v.frame.axes_are_identity()) return;
  const Mat3& a = v.frame.axes;  // rows: world directions of the grid axes
  // Normals transform by the inverse transpose of the linear map g -> sum_k g_k a[k].
  const Mat3 inv = inverse(a);
  for (std::size_t i = 0; i < mesh.vertex_count(); ++i) {
    float* p = &mesh.positions[3 * i];
    const Vec3d w = v.grid_to_world({double(p[0]), double(p[1]), double(p[2])});
    for (int c = 0; c < 3; ++c) p[c] = float(w[c]);
    float* n = &mesh.normals[3 * i];
    // n' = A^{-T} n with A's columns the axes: A = a^T, so A^{-T} = a^{-1}: n'_c = sum_k inv[c][k] n_k.
    double m[3] = {0, 0, 0}, len = 0;
    for (int c = 0; c < 3; ++c) {
      for (int k = 0; k < 3; ++k) m[c] += inv[c][k] * double(n[k]);
      len += m[c] * m[c];
    }
    len = std::sqrt(len);
    for (int c = 0; c < 3; ++c) n[c] = len > 0 ? float(m[c] / len) : n[c];
  }
  if (determinant(a) < 0)
    for (std::size_t t = 0; t < mesh.triangle_count(); ++t) std::swap(mesh.triangles[3 * t + 1], mesh.triangles[3 * t + 2]);
}

std::string ply_space_comment(const Volume& v) {
  if (v.frame.space.empty() || v.frame.space == "left-posterior-superior") return "SPACE=LPS";
  if (v.frame.space == "right-anterior-superior") return "SPACE=RAS";
  return "";
}

// ---------------------------------------------------------------------------------------------
// PLY

void write_ply_binary(const std::string& path, const Mesh& mesh, const std::string& comment) {
  if (io_detail::host_is_big_endian()) throw input_error(path, "binary PLY output needs a little-endian host");
  std::string header = "ply\nformat binary_little_endian 1.0\n";
  if (!comment.empty()) {
    std::string c = comment;
    std::replace(c.begin(), c.end(), '\r', ' ');
    std::size_t start = 0;
    while (start <= c.size()) {  // one "comment" line per line of it
      const std::size_t end = std::min(c.find('\n', start), c.size());
      header += "comment " + c.substr(start, end - start) + "\n";
      start = end + 1;
    }
  }
  header += "element vertex " + std::to_string(mesh.vertex_count()) +
            "\nproperty float x\nproperty float y\nproperty float z\n"
            "property float nx\nproperty float ny\nproperty float nz\n"
            "element face " + std::to_string(mesh.triangle_count()) +
            "\nproperty list uchar int vertex_indices\nend_header\n";
  io_detail::AtomicFile out(path);
  out.write(header.data(), header.size());
  std::vector<char> buf;
  const std::size_t chunk = 1 << 16;
  buf.reserve(chunk * 24);
  for (std::size_t i = 0; i < mesh.vertex_count(); ++i) {
    const float rec[6] = {mesh.positions[3 * i], mesh.positions[3 * i + 1], mesh.positions[3 * i + 2],
                          mesh.normals[3 * i],   mesh.normals[3 * i + 1],   mesh.normals[3 * i + 2]};
    buf.insert(buf.end(), reinterpret_cast<const char*>(rec), reinterpret_cast<const char*>(rec) + sizeof rec);
    if (buf.size() >= chunk * 24) out.write(buf.data(), buf.size()), buf.clear();
  }
  for (std::size_t t = 0; t < mesh.triangle_count(); ++t) {
    char rec[13];
    rec[0] = 3;
    for (int k = 0; k < 3; ++k) {
      const std::int32_t idx = std::int32_t(mesh.triangles[3 * t + k]);
      std::memcpy(rec + 1 + 4 * k, &idx, 4);
    }
    buf.insert(buf.end(), rec, rec + 13);
    if (buf.size() >= chunk * 24) out.write(buf.data(), buf.size()), buf.clear();
  }
  out.write(buf.data(), buf.size());
  out.commit();
}

Mesh read_ply_binary(const std::string& path) {
  io_detail::FilePtr f = io_detail::open_for_reading(path);
  auto bad = [&](const std::string& what) { return input_error(path, "not a softshell PLY: " + what); };
  std::string line;
  std::vector<std::string> lines;
  for (;;) {
    line.clear();
    int ch;
    while ((ch = std::fgetc(f.get())) != EOF && ch != '\n') line += char(ch);
    if (ch == EOF) throw bad("header ends early");
    lines.push_back(line);
    if (line == "end_header") break;
    if (lines.size() > 1000) throw bad("header too long");
  }
  if (lines.size() < 2 || lines[0] != "ply" || lines[1] != "format binary_little_endian 1.0")
    throw bad("expected 'ply' and 'format binary_little_endian 1.0'");
  std::size_t nv = 0, nf = 0;
  std::vector<std::string> props;
  for (const std::string& l : lines) {
    unsigned long long k = 0;
    if (std::sscanf(l.c_str(), "element vertex %llu", &k) == 1) nv = k;
    if (std::sscanf(l.c_str(), "element face %llu", &k) == 1) nf = k;
    if (l.rfind("property", 0) == 0) props.push_back(l);
  }
  const std::vector<std::string> want = {"property float x",  "property float y",  "property float z",
                                         "property float nx", "property float ny", "property float nz",
                                         "property list uchar int vertex_indices"};
  if (props != want) throw bad("unexpected properties");
  const std::uint64_t need = std::uint64_t(nv) * 24 + std::uint64_t(nf) * 13;
  const long pos = std::ftell(f.get());
  if (pos < 0 || io_detail::file_size(f.get()) != std::uint64_t(pos) + need)
    throw bad("size does not match the header (" + std::to_string(nv) + " vertices, " + std::to_string(nf) +
              " faces)");
  Mesh m;
  m.positions.resize(nv * 3);
  m.normals.resize(nv * 3);
  m.triangles.resize(nf * 3);
  std::vector<char> buf(need);
  io_detail::read_up_to(f.get(), buf.data(), need, path);
  for (std::size_t i = 0; i < nv; ++i) {
    float rec[6];
    std::memcpy(rec, buf.data() + 24 * i, 24);
    for (int a = 0; a < 3; ++a) m.positions[3 * i + a] = rec[a], m.normals[3 * i + a] = rec[3 + a];
  }
  const char* p = buf.data() + 24 * nv;
  for (std::size_t t = 0; t < nf; ++t, p += 13) {
    if (p[0] != 3) throw bad("face " + std::to_string(t) + " is not a triangle");
    for (int k = 0; k < 3; ++k) {
      std::int32_t idx;
      std::memcpy(&idx, p + 1 + 4 * k, 4);
      if (idx < 0 || std::size_t(idx) >= nv) throw bad("face " + std::to_string(t) + " has a bad vertex index");
      m.triangles[3 * t + k] = std::uint32_t(idx);
    }
  }
  return m;
}

// ---------------------------------------------------------------------------------------------
// Measures

namespace {
std::array<double, 3> vtx(const Mesh& m, std::uint32_t i) {
  return {m.positions[3 * i], m.positions[3 * i + 1], m.positions[3 * i + 2]};
}
}  // namespace

double mesh_area(const Mesh& m) {
  double area = 0;
  for (std::size_t t = 0; t < m.triangle_count(); ++t) {
    const auto a = vtx(m, m.triangles[3 * t]), b = vtx(m, m.triangles[3 * t + 1]), c = vtx(m, m.triangles[3 * t + 2]);
    const double u[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]}, w[3] = {c[0] - a[0], c[1] - a[1], c[2] - a[2]};
    const double n[3] = {u[1] * w[2] - u[2] * w[1], u[2] * w[0] - u[0] * w[2], u[0] * w[1] - u[1] * w[0]};
    area += 0.5 * std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
  }
  return area;
}

double mesh_signed_volume(const Mesh& m) {
  double vol = 0;
  for (std::size_t t = 0; t < m.triangle_count(); ++t) {
    const auto a = vtx(m, m.triangles[3 * t]), b = vtx(m, m.triangles[3 * t + 1]), c = vtx(m, m.triangles[3 * t + 2]);
    vol += a[0] * (b[1] * c[2] - b[2] * c[1]) - a[1] * (b[0] * c[2] - b[2] * c[0]) + a[2] * (b[0] * c[1] - b[1] * c[0]);
  }
  return vol / 6.0;
}

MeshTopology mesh_topology(const Mesh& m) {
  MeshTopology top;
  top.faces = m.triangle_count();
  // Directed edge counts: key = a * nv + b.
  const std::uint64_t nv = m.vertex_count();
  std::unordered_map<std::uint64_t, std::uint32_t> directed;
  directed.reserve(m.triangles.size() * 2);
  std::vector<std::uint32_t> parent(nv);
  std::iota(parent.begin(), parent.end(), 0u);
  auto find = [&](std::uint32_t x) {
    while (parent[x] != x) x = parent[x] = parent[parent[x]];
    return x;
  };
  std::vector<char> used(nv, 0);
  for (std::size_t t = 0; t < top.faces; ++t) {
    const std::uint32_t* v = &m.triangles[3 * t];
    if (v[0] == v[1] || v[1] == v[2] || v[0] == v[2]) ++top.degenerate_faces;
    for (int k = 0; k < 3; ++k) {
      used[v[k]] = 1;
      ++directed[std::uint64_t(v[k]) * nv + v[(k + 1) % 3]];
      const std::uint32_t a = find(v[k]), b = find(v[(k + 1) % 3]);
      if (a != b) parent[a] = b;
    }
  }
  for (std::uint64_t i = 0; i < nv; ++i)
    if (used[i]) {
      ++top.vertices;
      if (find(std::uint32_t(i)) == i) ++top.components;
    }
  for (const auto& [key, count] : directed) {
    const std::uint64_t a = key / nv, b = key % nv;
    const auto rev = directed.find(b * nv + a);
    const std::uint32_t back = rev == directed.end() ? 0 : rev->second;
    if (a < b || back == 0) {  // count each undirected edge once
      ++top.edges;
      const std::uint32_t total = count + back;
      if (total == 1) ++top.boundary_edges;
      else if (total > 2) ++top.nonmanifold_edges;
      else if (count != 1 || back != 1) ++top.misoriented_edges;
    }
  }
  return top;
}

}  // namespace softshell
