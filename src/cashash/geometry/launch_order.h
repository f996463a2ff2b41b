#pragma once

// The order in which a batched estimator lays its pairs out for the device.
//
// Why: the GPU verifier runs one block per pair and a call returns when its
// last block does. A call of a few hundred pairs fills the device several
// times over (F and H blocks several to an SM, E blocks one to an SM), so
// the blocks start in waves, in grid order. A pair with many matches scores
// every one of them in every trial; left where the pair list puts it, such a
// pair may start in the last wave and keep the whole call waiting on its own.
// Starting the largest first (longest-processing-time first) lets the small
// ones fill in behind them. Each pair's result depends only on its own seed
// and matches, so the order changes when a call ends, not what it returns.

#include <algorithm>
#include <cstddef>
#include <numeric>
#include <vector>

namespace cashash {

// Indices into `work`, the largest first; equal ones keep their order, so the
// launch is the same for the same input.
inline std::vector<size_t> LargestFirst(const std::vector<size_t>& work) {
  std::vector<size_t> order(work.size());
  std::iota(order.begin(), order.end(), size_t{0});
  std::stable_sort(order.begin(), order.end(), [&](size_t a, size_t b) { return work[a] > work[b]; });
  return order;
}

}  // namespace cashash
