// Triangle meshes from Marching Cubes (kernels/mc.cl) and what the tests and the `mesh` command
// need around them: binary PLY output (and input, to check it), area, enclosed volume and the
// topology (Euler characteristic, boundary and non-manifold edges). GL-free, in softshell_core.
//
// Conventions: positions in mm (origin + spacing * index), indexed triangles (one vertex per
// crossing grid edge, shared by every cell around it), normals = -grad f / |grad f| (pointing
// towards lower values, i.e. out of the region above the level), triangles wound
// counter-clockwise around their normals. For an opacity volume the region above the level is
// the shell, so normals point out of it and the enclosed volume is positive.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "cl_runtime.hpp"
#include "volume.hpp"

namespace softshell {

struct Mesh {
  std::vector<float> positions;         // 3 per vertex, mm
  std::vector<float> normals;           // 3 per vertex, unit
  std::vector<std::uint32_t> triangles; // 3 vertex indices per triangle

  std::size_t vertex_count() const { return positions.size() / 3; }
  std::size_t triangle_count() const { return triangles.size() / 3; }
  bool empty() const { return triangles.empty(); }
  // Bounding box of the vertices (mm); {0, 0} boxes for an empty mesh.
  std::array<Vec3d, 2> bounds() const;
  // Bytes held on the host.
  std::size_t memory_bytes() const;
};

// Seconds spent in each stage (device stages from profiling events).
struct MeshTiming {
  double classify = 0;   // mc_classify on the device
  double scan = 0;       // read-back of masks/cases, host scans, upload of offsets
  double generate = 0;   // mc_vertices + mc_triangles on the device
  double read = 0;       // read-back of the mesh
  double total = 0;      // wall clock, upload of the volume included
};

// Marching Cubes of `v` at `level` on the device of `rt`. Throws InputError for a volume with
// fewer than 2 samples along an axis or a non-finite level; a level outside the data's range
// gives an empty mesh. Deterministic: vertices in (grid point, axis) order, triangles in cell
// order, bit-identical run to run.
Mesh marching_cubes(Runtime& rt, const Volume& v, double level, MeshTiming* timing = nullptr);

// The same algorithm on the host, in float64, one cell at a time (the tests' reference).
Mesh marching_cubes_reference(const Volume& v, double level);

// Moves a mesh from grid millimetres (origin + spacing * index: where marching_cubes puts it)
// into the world of `v` (Volume::grid_to_world): positions through the volume's axes about its
// origin, normals through the inverse transpose and renormalised, and the triangles' winding
// reversed when the axes are left-handed (a mirror), so triangles stay counter-clockwise around
// their normals. Nothing changes when the axes are the identity.
void mesh_to_world(Mesh& mesh, const Volume& v);

// The PLY comment that tells 3D Slicer the mesh's coordinate system ("SPACE=LPS" or
// "SPACE=RAS", Slicer's own convention), for a mesh in `v`'s world; empty when that world
// is not a patient space.
std::string ply_space_comment(const Volume& v);

// Binary little-endian PLY: vertex float x y z nx ny nz, face list uchar int vertex_indices;
// written atomically (nothing is left behind on failure). `comment` goes into the header, one
// "comment" line per line of it.
void write_ply_binary(const std::string& path, const Mesh& mesh, const std::string& comment = "");
// Reads what write_ply_binary writes (binary little-endian, those properties); InputError
// naming the file and the problem otherwise.
Mesh read_ply_binary(const std::string& path);

double mesh_area(const Mesh& mesh);            // mm^2
double mesh_signed_volume(const Mesh& mesh);   // mm^3, divergence theorem; > 0 when normals point out

struct MeshTopology {
  std::size_t vertices = 0;          // referenced by some triangle
  std::size_t edges = 0;             // undirected
  std::size_t faces = 0;
  std::size_t boundary_edges = 0;    // used by one triangle
  std::size_t nonmanifold_edges = 0; // used by more than two
  std::size_t misoriented_edges = 0; // two triangles traverse it in the same direction
  std::size_t degenerate_faces = 0;  // a repeated vertex index
  std::size_t components = 0;        // connected through shared vertices
  long euler() const { return long(vertices) - long(edges) + long(faces); }
  bool closed() const { return boundary_edges == 0 && nonmanifold_edges == 0 && misoriented_edges == 0; }
};
MeshTopology mesh_topology(const Mesh& mesh);

}  // namespace softshell
