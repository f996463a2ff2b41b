// One bit for each unordered pair of n positions (i < j): which pairs of a
// run are already done. n(n-1)/2 bits, allocated on the first Set, so that
// a run that resumes nothing holds none (20,000 images: 25 MiB otherwise).
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

namespace cashash {

class PairTriangle {
 public:
  PairTriangle() = default;
  explicit PairTriangle(size_t n) : n_(n) {}

  size_t size() const { return n_; }  // positions
  // Sets pair (i, j), i != j, both < size(); false when it was set already.
  bool Set(size_t i, size_t j);
  bool Test(size_t i, size_t j) const;
  // Set pairs (a, b) for b in [b_begin, b_end), each b > a.
  size_t CountInRow(size_t a, size_t b_begin, size_t b_end) const;
  size_t count() const { return count_; }
  bool empty() const { return count_ == 0; }
  size_t memory_bytes() const { return words_.capacity() * sizeof(uint64_t); }
  // The bits, 64 pairs a word in row-major order of the upper triangle
  // (empty while nothing is set).
  const std::vector<uint64_t>& words() const { return words_; }

 private:
  uint64_t BitOf(size_t i, size_t j) const;

  size_t n_ = 0;
  size_t count_ = 0;
  std::vector<uint64_t> words_;
};

}  // namespace cashash
