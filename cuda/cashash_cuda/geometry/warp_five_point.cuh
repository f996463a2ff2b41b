// The 5-point solver on a given basis by one warp: E's local refit. On one
// lane, the Sturm isolation of the degree-10 polynomial's roots and their
// polishing kept the E block's seven other warps waiting at the barrier
// after the refit (ncu: 30 % of the E kernel's stall samples;
// on the host the roots are about half of five_point::SolveFromBasis). Here
// - lane 0 eliminates, builds the determinant and its Sturm sequence (as
//   on one lane: the 10 x 20 elimination by the warp gained only 2 %);
// - every sign-variation count of the isolation evaluates the sequence's
//   polynomials on separate lanes (lane k the k-th), which every lane then
//   counts alike, so all lanes take the same splits;
// - lane r polishes root r and builds its model.
// Each value is computed by the same function as on one thread, so the
// models are five_point::SolveFromBasis's to the bit (gpu_essential_test).
// This made verification 7-11 % faster on 300-image streets.
#pragma once

#include <cuda_runtime.h>

#include "cashash/geometry/five_point_solver.h"
#include "cashash/geometry/sturm_roots.h"

namespace cashash {
namespace cuda {

// Shared memory of one warp's solve.
struct WarpFivePointScratch {
  double basis[4][9];  // the caller's lane 0 writes it
  five_point::DeterminantSystem system;
  sturm::SturmSequence sequence;
  int solvable;  // the elimination and the sequence succeeded
};

// Every lane of the warp calls it, after lane 0 has written s.basis. Returns
// the number of models on every lane; the models go to `models` (shared
// memory, up to five_point::kMaxSolutions) in SolveFromBasis' order.
// Not inlined: inside the E kernel, which is at its register limit, it would
// spill.
__device__ __noinline__ inline int WarpSolveFromBasis(WarpFivePointScratch& s, double (*models)[9]) {
  const int lane = threadIdx.x % 32;
  if (lane == 0) {
    s.solvable = five_point::EliminateToDeterminant(s.basis, &s.system) &&
                 sturm::BuildSturmSequence(s.system.det, 10, &s.sequence);
  }
  __syncwarp();
  if (!s.solvable) return 0;  // the same answer on every lane
  const sturm::SturmSequence& seq = s.sequence;
  auto variations = [&seq, lane](double t) {
    const double value = lane < seq.length ? sturm::Horner(seq.S[lane], seq.deg[lane], t) : 0.0;
    double values[sturm::kMaxSturmLength];
#pragma unroll
    for (int k = 0; k < sturm::kMaxSturmLength; ++k) values[k] = __shfl_sync(0xffffffffu, value, k);
    return sturm::SignChanges(values, seq.length);
  };
  sturm::RootInterval intervals[sturm::kMaxDegree];
  const int num_roots = sturm::IsolateRoots(seq, variations, intervals);
  double e[9];
  bool found = false;
  if (lane < num_roots) {
    const double z = sturm::RootIn(seq, intervals[lane]);
    found = five_point::ModelAtRoot(s.basis, s.system, z, e);
  }
  const unsigned found_lanes = __ballot_sync(0xffffffffu, found);
  if (found) {
    const int slot = __popc(found_lanes & ((1u << lane) - 1u));
    for (int k = 0; k < 9; ++k) models[slot][k] = e[k];
  }
  __syncwarp();
  return __popc(found_lanes);
}

}  // namespace cuda
}  // namespace cashash
