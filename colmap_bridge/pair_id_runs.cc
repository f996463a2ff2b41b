#include "colmap_bridge/pair_id_runs.h"

#include <algorithm>

#include "colmap_bridge/database.h"

namespace cashash {
namespace colmap {
namespace {

void PutVarint(uint64_t value, std::vector<uint8_t>* out) {
  while (value >= 0x80) {
    out->push_back(static_cast<uint8_t>(value | 0x80));
    value >>= 7;
  }
  out->push_back(static_cast<uint8_t>(value));
}

// Reads one varint at *pos; false when the blob ends inside it or it does
// not fit 64 bits.
bool GetVarint(const uint8_t* bytes, size_t num_bytes, size_t* pos, uint64_t* value) {
  *value = 0;
  for (int shift = 0; shift < 64; shift += 7) {
    if (*pos >= num_bytes) return false;
    const uint8_t byte = bytes[(*pos)++];
    if (shift == 63 && (byte & 0x7E) != 0) return false;
    *value |= static_cast<uint64_t>(byte & 0x7F) << shift;
    if ((byte & 0x80) == 0) return true;
  }
  return false;
}

}  // namespace

std::vector<uint8_t> EncodePairIdRuns(std::vector<pair_t> pair_ids) {
  std::sort(pair_ids.begin(), pair_ids.end());
  pair_ids.erase(std::unique(pair_ids.begin(), pair_ids.end()), pair_ids.end());
  std::vector<uint8_t> out;
  pair_t next = 0;  // one past the end of the previous run
  for (size_t i = 0; i < pair_ids.size();) {
    size_t j = i + 1;
    while (j < pair_ids.size() && pair_ids[j] == pair_ids[j - 1] + 1) ++j;
    PutVarint(pair_ids[i] - next, &out);
    PutVarint(j - i, &out);
    next = pair_ids[j - 1] + 1;
    i = j;
  }
  return out;
}

void DecodePairIdRuns(const void* data, size_t num_bytes, const std::string& owner,
                      const std::function<void(pair_t first, pair_t last)>& run) {
  const uint8_t* bytes = static_cast<const uint8_t*>(data);
  size_t pos = 0;
  pair_t next = 0;
  while (pos < num_bytes) {
    uint64_t gap = 0, length = 0;
    if (!GetVarint(bytes, num_bytes, &pos, &gap) || !GetVarint(bytes, num_bytes, &pos, &length)) {
      throw DatabaseError(owner + ": truncated run at byte " + std::to_string(pos));
    }
    pair_t first = 0, last = 0;
    if (length == 0 || __builtin_add_overflow(next, gap, &first) || __builtin_add_overflow(first, length - 1, &last) ||
        last == UINT64_MAX) {
      throw DatabaseError(owner + ": run of " + std::to_string(length) + " pair ids out of range at byte " +
                          std::to_string(pos));
    }
    run(first, last);
    next = last + 1;
  }
}

}  // namespace colmap
}  // namespace cashash
