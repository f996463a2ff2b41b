#include "cashash/pipeline/pair_triangle.h"

#include <algorithm>
#include <bitset>
#include <utility>

namespace cashash {

uint64_t PairTriangle::BitOf(size_t i, size_t j) const {
  if (i > j) std::swap(i, j);
  const uint64_t n = n_, a = i, b = j;
  // Row a of the upper triangle starts after a rows of n-1, n-2, ... pairs.
  return a * n - a * (a + 1) / 2 + (b - a - 1);
}

bool PairTriangle::Set(size_t i, size_t j) {
  if (words_.empty()) words_.assign((n_ * (n_ > 0 ? n_ - 1 : 0) / 2 + 63) / 64, 0);
  const uint64_t bit = BitOf(i, j);
  uint64_t& word = words_[bit / 64];
  const uint64_t mask = uint64_t{1} << (bit % 64);
  if (word & mask) return false;
  word |= mask;
  ++count_;
  return true;
}

bool PairTriangle::Test(size_t i, size_t j) const {
  if (words_.empty()) return false;
  const uint64_t bit = BitOf(i, j);
  return (words_[bit / 64] >> (bit % 64)) & 1;
}

size_t PairTriangle::CountInRow(size_t a, size_t b_begin, size_t b_end) const {
  if (words_.empty() || b_begin >= b_end) return 0;
  // The row's bits for b_begin..b_end-1 are consecutive.
  uint64_t bit = BitOf(a, b_begin);
  const uint64_t end = bit + (b_end - b_begin);
  size_t count = 0;
  while (bit < end) {
    const uint64_t offset = bit % 64;
    const uint64_t take = std::min<uint64_t>(64 - offset, end - bit);
    uint64_t word = words_[bit / 64] >> offset;
    if (take < 64) word &= (uint64_t{1} << take) - 1;
    count += std::bitset<64>(word).count();
    bit += take;
  }
  return count;
}

}  // namespace cashash
