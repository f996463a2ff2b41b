// A compact record of many pair ids: sorted, cut into runs of consecutive
// ids, each run stored as (gap from the previous run, length) in LEB128
// varints. Exhaustive matching walks image j for a fixed image i, whose pair
// ids are consecutive, so a block of 50 x 50 empty pairs takes a few
// hundred bytes instead of 2,500 rows in each of two tables.
#pragma once

#include <cstddef>
#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "cashash/base/types.h"

namespace cashash {
namespace colmap {

// Any order, repeats allowed.
std::vector<uint8_t> EncodePairIdRuns(std::vector<pair_t> pair_ids);

// Calls run(first, last) for every run [first, last] in increasing order.
// Throws DatabaseError naming `owner` on a truncated or overflowing blob.
void DecodePairIdRuns(const void* data, size_t num_bytes, const std::string& owner,
                      const std::function<void(pair_t first, pair_t last)>& run);

}  // namespace colmap
}  // namespace cashash
