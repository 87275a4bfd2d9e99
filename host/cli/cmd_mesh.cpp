// `softshell mesh IN --level L -o OUT.ply`: Marching Cubes (kernels/mc.cl) on any volume at a
// level, written as binary little-endian PLY (MeshLab, ParaView, Blender read it).
#include <algorithm>
#include <cmath>
#include <iomanip>
#include <iostream>
#include <memory>
#include <optional>
#include <sstream>

#include "cl_runtime.hpp"
#include "cli_common.hpp"
#include "cli_validate.hpp"
#include "error.hpp"
#include "progress.hpp"
#include "io.hpp"
#include "mesh.hpp"

namespace softshell::cli {
namespace {

struct MeshOptions {
  std::string in, out, device;
  std::string coordinates = "world";
  double level = std::nan("");
  bool quiet = false;
  RawOptions raw;
  NonFiniteOption non_finite;
};

int run_mesh(const MeshOptions& o) {
  const auto t0 = Clock::now();
  if (!std::isfinite(o.level)) throw InputError("--level must be a finite number");
  if (o.out.size() < 4 || o.out.substr(o.out.size() - 4) != ".ply")
    throw InputError("-o " + o.out + ": expected a .ply file");
  ensure_distinct_output(o.in, o.out);
  check_output(o.out, OutputKind::Ply);
  Volume v = read_volume(o.in, o.raw.spec(), o.raw.frame);
  o.non_finite.apply(v, o.in);
  for (int a = 0; a < 3; ++a)
    if (v.dims[a] < 2) throw input_error(o.in, "Marching Cubes needs at least 2 samples along every axis");

  std::optional<progress::Stage> stage(std::in_place, "mesh");
  Runtime rt(o.device);
  MeshTiming mt;
  Mesh mesh = marching_cubes(rt, v, o.level, &mt);
  const bool world = o.coordinates == "world";
  if (world) mesh_to_world(mesh, v);
  if (mesh.empty()) {
    const auto [lo, hi] = std::minmax_element(v.data.begin(), v.data.end());
    std::ostringstream msg;
    msg << "no surface at level " << o.level << " (values span [" << *lo << ", " << *hi << "])";
    throw input_error(o.in, msg.str());
  }
  const auto tw = Clock::now();
  std::ostringstream comment;
  comment << "softshell marching cubes of " << o.in << " at level " << o.level << "; mm, "
          << (world ? "the volume's world coordinates" : "grid coordinates (origin + spacing * index)")
          << "; normals point towards lower values";
  if (world && !ply_space_comment(v).empty()) comment << '\n' << ply_space_comment(v);
  write_ply_binary(o.out, mesh, comment.str());
  stage.reset();
  const double write_s = seconds_since(tw);

  if (!o.quiet) {
    const MeshTopology top = mesh_topology(mesh);
    const auto box = mesh.bounds();
    std::cout << std::fixed << std::setprecision(3) << "mesh " << o.in << " -> " << o.out << '\n'
              << "  level    " << o.level << '\n'
              << "  mesh     " << mesh.vertex_count() << " vertices, " << mesh.triangle_count() << " triangles, "
              << top.components << " component(s), Euler characteristic " << top.euler() << ", "
              << (top.closed() ? "closed" : std::to_string(top.boundary_edges) + " boundary edges") << '\n'
              << "  size     area " << std::setprecision(1) << mesh_area(mesh) << " mm^2, enclosed volume "
              << mesh_signed_volume(mesh) << " mm^3, box [" << box[0][0] << ", " << box[1][0] << "] x ["
              << box[0][1] << ", " << box[1][1] << "] x [" << box[0][2] << ", " << box[1][2] << "] mm\n"
              << std::setprecision(1) << "  time     classify " << 1e3 * mt.classify << " ms, scan " << 1e3 * mt.scan
              << " ms, vertices+triangles " << 1e3 * mt.generate << " ms, read-back " << 1e3 * mt.read
              << " ms (extraction " << 1e3 * mt.total << " ms on " << rt.info().label() << "), PLY "
              << 1e3 * write_s << " ms, total " << std::setprecision(3) << seconds_since(t0) << " s\n";
  }
  return 0;
}

}  // namespace

void add_mesh_command(CLI::App& app, Action& action) {
  auto o = std::make_shared<MeshOptions>();
  auto* sub = app.add_subcommand(
      "mesh",
      "Extract the isosurface of a volume at a level with Marching Cubes (OpenCL) and write it as binary PLY "
      "(positions in mm, per-vertex normals from the gradient, indexed and closed where the surface does not "
      "leave the volume). On an opacity volume, --level 0.5 gives the middle of the soft shells.");
  sub->add_option("IN", o->in, "Input volume (any scalar type; an opacity volume, raw data, a distance field)")
      ->required();
  sub->add_option("--level", o->level, "Isovalue, in the volume's own units (e.g. 0.5 for an opacity volume)")
      ->required()
      ->check(real_range(-INFINITY, INFINITY));
  sub->add_option("-o,--output", o->out, "Output mesh (.ply, binary little-endian)")->required();
  sub->add_option("--coordinates", o->coordinates,
                  "world: positions in the volume's world coordinates (its origin, spacing and orientation: "
                  "the mesh overlays the volume in 3D Slicer, ITK, ParaView); grid: origin + spacing * index, "
                  "ignoring the orientation (the same as world for axis-aligned volumes)")
      ->check(CLI::IsMember({"world", "grid"}))
      ->default_str("world");
  sub->add_flag("-q,--quiet", o->quiet, "Print nothing on success");
  o->raw.add_to(sub);
  o->non_finite.add_to(sub);
  add_device_option(sub, o->device);
  sub->callback([&action, o] { action = [o] { return run_mesh(*o); }; });
}

}  // namespace softshell::cli
