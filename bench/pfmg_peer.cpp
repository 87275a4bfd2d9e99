// HYPRE's structured multigrid as the bench's peer (docs/benchmarks.md,
// "Peers"): PFMG-preconditioned conjugate gradients through HYPRE's Struct
// interface on the system softshell assembled (exported by `softshell
// bench`), in float64, on MPI ranks (Debian's HYPRE has no OpenMP), the
// volume split in z-slabs, one per rank.
//
//   mpirun -n R softshell_pfmg_peer SYSTEM.bin RESULT.bin TOL
//
// SYSTEM.bin: "SSPFMG1\0", int32 nx, ny, nz, then the STENCIL_COEFS x N
// float32 coefficients (kernels/stencil.h, structure of arrays) and the N
// float32 b. RESULT.bin (rank 0): "SSPFMGR\0", double setup_s, solve_s,
// final relative residual (HYPRE's), int64 iterations, then N float64 u.
// Settings: PCG with the 2-norm relative residual, no relative-change test;
// PFMG as the preconditioner, one V(1,1) cycle from zero, weighted Jacobi
// (HYPRE's default; its red/black Gauss-Seidel is for 5/7-point stencils
// only and aborts on this 19-point one), Galerkin coarse operators, skip
// relaxation off: the settings of HYPRE's own struct driver for PFMG-PCG.
#include <HYPRE_struct_ls.h>
#include <mpi.h>

#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <string>
#include <vector>

#include "stencil.h"

namespace {

int fail(const std::string& what) {
  std::fprintf(stderr, "softshell_pfmg_peer: %s\n", what.c_str());
  MPI_Abort(MPI_COMM_WORLD, 2);
  return 2;
}

}  // namespace

int main(int argc, char** argv) {
  MPI_Init(&argc, &argv);
  int rank = 0, ranks = 1;
  MPI_Comm_rank(MPI_COMM_WORLD, &rank);
  MPI_Comm_size(MPI_COMM_WORLD, &ranks);
  if (argc != 4) return fail("usage: softshell_pfmg_peer SYSTEM.bin RESULT.bin TOL");
  const double tol = std::atof(argv[3]);
  if (!(tol > 0)) return fail("TOL must be > 0");
  // Every rank reads the header and its own planes (plus nothing more: the
  // off-slab couplings it needs come with the rows it owns).
  std::ifstream in(argv[1], std::ios::binary);
  char magic[8];
  std::int32_t dims[3];
  if (!in.read(magic, 8) || std::memcmp(magic, "SSPFMG1", 8) != 0 || !in.read(reinterpret_cast<char*>(dims), sizeof dims))
    return fail(std::string(argv[1]) + ": not a softshell system file");
  const long nx = dims[0], ny = dims[1], nz = dims[2];
  const std::size_t N = std::size_t(nx) * ny * nz;
  std::vector<float> coef(STENCIL_COEFS * N), b(N);
  if (!in.read(reinterpret_cast<char*>(coef.data()), std::streamsize(coef.size() * 4)) ||
      !in.read(reinterpret_cast<char*>(b.data()), std::streamsize(b.size() * 4)))
    return fail(std::string(argv[1]) + ": truncated");
  const int table[STENCIL_COEFS][3] = {
#define SOFTSHELL_OFF(K, DX, DY, DZ) {DX, DY, DZ},
      STENCIL_OFFSETS(SOFTSHELL_OFF)
#undef SOFTSHELL_OFF
  };
  // The 19 entries: the centre, the 9 stored offsets, their 9 opposites.
  HYPRE_Int offsets[2 * STENCIL_COEFS - 1][3];
  for (int k = 0; k < STENCIL_COEFS; ++k)
    for (int a = 0; a < 3; ++a) offsets[k][a] = table[k][a];
  for (int k = 1; k < STENCIL_COEFS; ++k)
    for (int a = 0; a < 3; ++a) offsets[STENCIL_COEFS - 1 + k][a] = -table[k][a];
  const int entries = 2 * STENCIL_COEFS - 1;
  const long z0 = nz * rank / ranks, z1 = nz * (rank + 1) / ranks;  // this rank's planes
  HYPRE_Int lower[3] = {0, 0, HYPRE_Int(z0)}, upper[3] = {HYPRE_Int(nx - 1), HYPRE_Int(ny - 1), HYPRE_Int(z1 - 1)};

  HYPRE_StructGrid grid;
  HYPRE_StructGridCreate(MPI_COMM_WORLD, 3, &grid);
  if (z1 > z0) HYPRE_StructGridSetExtents(grid, lower, upper);
  HYPRE_StructGridAssemble(grid);
  HYPRE_StructStencil stencil;
  HYPRE_StructStencilCreate(3, entries, &stencil);
  for (int e = 0; e < entries; ++e) HYPRE_StructStencilSetElement(stencil, e, offsets[e]);
  HYPRE_StructMatrix A;
  HYPRE_StructMatrixCreate(MPI_COMM_WORLD, grid, stencil, &A);
  HYPRE_StructMatrixInitialize(A);
  HYPRE_StructVector vb, vx;
  HYPRE_StructVectorCreate(MPI_COMM_WORLD, grid, &vb);
  HYPRE_StructVectorCreate(MPI_COMM_WORLD, grid, &vx);
  HYPRE_StructVectorInitialize(vb);
  HYPRE_StructVectorInitialize(vx);
  const std::size_t local = std::size_t(nx) * ny * std::size_t(z1 - z0);
  std::vector<double> values(local * entries), bv(local), xv(local, 0.0);
  long sy = nx, sz = nx * ny;
  std::size_t m = 0;
  for (long z = z0; z < z1; ++z)
    for (long y = 0; y < ny; ++y)
      for (long x = 0; x < nx; ++x, ++m) {
        const std::size_t p = std::size_t(x + sy * y + sz * z);
        const bool edge = x == 0 || y == 0 || z == 0 || x == nx - 1 || y == ny - 1 || z == nz - 1;
        double* row = &values[m * entries];
        row[0] = coef[p];
        for (int k = 1; k < STENCIL_COEFS; ++k) {
          const long off = table[k][0] + sy * table[k][1] + sz * table[k][2];
          row[k] = edge ? 0.0 : double(coef[k * N + p]);
          row[STENCIL_COEFS - 1 + k] = edge ? 0.0 : double(coef[k * N + std::size_t(long(p) - off)]);
        }
        bv[m] = b[p];
      }
  std::vector<HYPRE_Int> idx(entries);
  for (int e = 0; e < entries; ++e) idx[e] = e;
  if (z1 > z0) {
    HYPRE_StructMatrixSetBoxValues(A, lower, upper, entries, idx.data(), values.data());
    HYPRE_StructVectorSetBoxValues(vb, lower, upper, bv.data());
    HYPRE_StructVectorSetBoxValues(vx, lower, upper, xv.data());
  }
  HYPRE_StructMatrixAssemble(A);
  HYPRE_StructVectorAssemble(vb);
  HYPRE_StructVectorAssemble(vx);
  coef.clear(), coef.shrink_to_fit();
  // Timed from here: the solver's setup (PFMG's hierarchy) and its solve;
  // loading the matrix into HYPRE is the peer's counterpart of softshell's
  // assembly, which softshell's time leaves out too.
  MPI_Barrier(MPI_COMM_WORLD);
  const double t0 = MPI_Wtime();

  HYPRE_StructSolver pcg, pfmg;
  HYPRE_StructPCGCreate(MPI_COMM_WORLD, &pcg);
  HYPRE_StructPCGSetTol(pcg, tol);
  HYPRE_StructPCGSetTwoNorm(pcg, 1);
  HYPRE_StructPCGSetRelChange(pcg, 0);
  HYPRE_StructPCGSetMaxIter(pcg, 500);
  HYPRE_StructPFMGCreate(MPI_COMM_WORLD, &pfmg);
  HYPRE_StructPFMGSetMaxIter(pfmg, 1);
  HYPRE_StructPFMGSetTol(pfmg, 0.0);
  HYPRE_StructPFMGSetZeroGuess(pfmg);
  HYPRE_StructPFMGSetRelaxType(pfmg, 1);  // weighted Jacobi (red/black GS needs a 7-point stencil)
  HYPRE_StructPFMGSetNumPreRelax(pfmg, 1);
  HYPRE_StructPFMGSetNumPostRelax(pfmg, 1);
  HYPRE_StructPFMGSetRAPType(pfmg, 0);
  HYPRE_StructPFMGSetSkipRelax(pfmg, 0);
  HYPRE_StructPCGSetPrecond(pcg, HYPRE_StructPFMGSolve, HYPRE_StructPFMGSetup, pfmg);
  HYPRE_StructPCGSetup(pcg, A, vb, vx);
  MPI_Barrier(MPI_COMM_WORLD);
  const double t1 = MPI_Wtime();
  HYPRE_StructPCGSolve(pcg, A, vb, vx);
  MPI_Barrier(MPI_COMM_WORLD);
  const double t2 = MPI_Wtime();
  HYPRE_Int iterations = 0;
  double rel = 0;
  HYPRE_StructPCGGetNumIterations(pcg, &iterations);
  HYPRE_StructPCGGetFinalRelativeResidualNorm(pcg, &rel);
  if (z1 > z0) HYPRE_StructVectorGetBoxValues(vx, lower, upper, xv.data());
  // Gather u on rank 0, slabs in rank order (z order).
  std::vector<int> counts(ranks), displs(ranks);
  for (int r = 0; r < ranks; ++r) {
    const long a = nz * r / ranks, c = nz * (r + 1) / ranks;
    counts[r] = int(std::size_t(nx) * ny * std::size_t(c - a));
    displs[r] = int(std::size_t(nx) * ny * std::size_t(a));
  }
  std::vector<double> u(rank == 0 ? N : 0);
  MPI_Gatherv(xv.data(), int(local), MPI_DOUBLE, u.data(), counts.data(), displs.data(), MPI_DOUBLE, 0, MPI_COMM_WORLD);
  if (rank == 0) {
    std::ofstream out(argv[2], std::ios::binary);
    const double head[3] = {t1 - t0, t2 - t1, rel};
    const std::int64_t it = iterations;
    out.write("SSPFMGR", 8);
    out.write(reinterpret_cast<const char*>(head), sizeof head);
    out.write(reinterpret_cast<const char*>(&it), sizeof it);
    out.write(reinterpret_cast<const char*>(u.data()), std::streamsize(N * sizeof(double)));
    if (!out) return fail(std::string(argv[2]) + ": cannot write");
  }
  HYPRE_StructPCGDestroy(pcg);
  HYPRE_StructPFMGDestroy(pfmg);
  HYPRE_StructMatrixDestroy(A);
  HYPRE_StructVectorDestroy(vb);
  HYPRE_StructVectorDestroy(vx);
  HYPRE_StructStencilDestroy(stencil);
  HYPRE_StructGridDestroy(grid);
  MPI_Finalize();
  return 0;
}
