#include "cashash/retrieval/visual_words.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include <Eigen/Core>

#include "cashash/matching/cascade_hashing.h"

namespace cashash {
namespace {

// The retrieval tables draw their own projections: the seed is offset so
// that they are not the matcher's first tables (a word would then be a
// matcher bucket, and the two would share their misses).
constexpr uint64_t kRetrievalSeedOffset = 0x5245545249455645ull;  // "RETRIEVE"

using RowMatrix = Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;

}  // namespace

std::vector<uint32_t> NearestCellFlips(const float* margins, int bits, int num_probes) {
  uint32_t masks[kMaxCellFlips];
  const int count = NearestCellFlips(margins, bits, num_probes, masks);
  return std::vector<uint32_t>(masks, masks + count);
}

int NearestCellFlips(const float* margins, int bits, int num_probes, uint32_t* masks) {
  if (num_probes <= 1 || bits < 1) return 0;
  // The four least certain bits, by margin then index (insertion into a
  // list of four: no allocation, this runs for every feature and table).
  constexpr int kConsidered = 4;
  int order[kConsidered];
  int considered = 0;
  for (int i = 0; i < bits; ++i) {
    int k = considered < kConsidered ? considered++ : kConsidered;
    if (k == kConsidered) {
      if (!(margins[i] < margins[order[kConsidered - 1]])) continue;
      k = kConsidered - 1;
    }
    while (k > 0 && margins[i] < margins[order[k - 1]]) {
      order[k] = order[k - 1];
      --k;
    }
    order[k] = i;
  }
  struct Flip {
    float cost;
    uint32_t mask;
  };
  Flip flips[kConsidered + kConsidered * (kConsidered - 1) / 2];
  int num_flips = 0;
  for (int a = 0; a < considered; ++a) {
    const float ma = margins[order[a]];
    flips[num_flips++] = {ma * ma, uint32_t{1} << order[a]};
    for (int b = a + 1; b < considered; ++b) {
      const float mb = margins[order[b]];
      flips[num_flips++] = {ma * ma + mb * mb, (uint32_t{1} << order[a]) | (uint32_t{1} << order[b])};
    }
  }
  std::stable_sort(flips, flips + num_flips, [](const Flip& x, const Flip& y) { return x.cost < y.cost; });
  const int count = std::min(num_flips, num_probes - 1);
  for (int k = 0; k < count; ++k) masks[k] = flips[k].mask;
  return count;
}

VisualWordHasher::VisualWordHasher(const RetrievalOptions& options, int bits_per_word, const MeanDescriptor& mean) {
  const std::string problem = options.Check();
  if (!problem.empty()) throw std::invalid_argument(problem);
  if (bits_per_word < RetrievalOptions::kMinBitsPerWord || bits_per_word > RetrievalOptions::kMaxBitsPerWord) {
    throw std::invalid_argument("VisualWordHasher: bits_per_word must be in [" +
                                std::to_string(RetrievalOptions::kMinBitsPerWord) + ", " +
                                std::to_string(RetrievalOptions::kMaxBitsPerWord) + "], got " +
                                std::to_string(bits_per_word));
  }
  num_tables_ = options.num_tables;
  bits_per_word_ = bits_per_word;
  num_probes_ = options.num_nearest_neighbors;
  // The cascade's projection generator (integer entries, the same on
  // every platform). It draws its rows in order, so the first num_rows
  // rows of any larger request are the same: ask for tables of 20 bits
  // until there are enough.
  const int num_rows = num_tables_ * bits_per_word_;
  CasHashOptions cascade;
  cascade.random_seed = options.random_seed + kRetrievalSeedOffset;
  cascade.bits_per_table = 20;
  cascade.num_tables = (num_rows + cascade.bits_per_table - 1) / cascade.bits_per_table;
  const std::vector<float> drawn = GenerateCascadeProjections(cascade).matrix;
  rows_.assign(drawn.begin(), drawn.begin() + static_cast<size_t>(num_rows) * kDescriptorDim);
  row_norms_.resize(num_rows);
  for (int r = 0; r < num_rows; ++r) {
    double sum = 0;
    for (int d = 0; d < kDescriptorDim; ++d) {
      const double v = rows_[static_cast<size_t>(r) * kDescriptorDim + d];
      sum += v * v;
    }
    row_norms_[r] = static_cast<float>(std::sqrt(std::max(sum, 1.0)));
  }
  rounded_mean_.resize(kDescriptorDim);
  for (int d = 0; d < kDescriptorDim; ++d) rounded_mean_[d] = std::clamp(std::round(mean[d]), 0.f, 255.f);
}

ImageWords VisualWordHasher::Words(const FeatureDescriptors& descriptors, const std::vector<uint32_t>& rows) const {
  const size_t n = rows.empty() ? descriptors.rows() : rows.size();
  for (uint32_t row : rows) {
    if (row >= descriptors.rows()) throw std::invalid_argument("VisualWordHasher::Words: row past the descriptors");
  }
  const int num_rows = num_tables_ * bits_per_word_;
  // x = descriptor - rounded mean: integers in [-255, 255]; every dot
  // product with the integer rows is an integer below 2^24 in magnitude,
  // so float arithmetic gives it exactly in any order (cascade_hashing.h).
  RowMatrix x(static_cast<Eigen::Index>(n), kDescriptorDim);
  for (size_t i = 0; i < n; ++i) {
    const uint8_t* d = descriptors.row(rows.empty() ? i : rows[i]);
    for (int k = 0; k < kDescriptorDim; ++k) x(static_cast<Eigen::Index>(i), k) = d[k] - rounded_mean_[k];
  }
  const Eigen::Map<const RowMatrix> w(rows_.data(), num_rows, kDescriptorDim);
  const RowMatrix dots = x * w.transpose();

  ImageWords words;
  words.indexed.resize(n * num_tables_);
  if (num_probes_ > 1) words.query.reserve(n * num_tables_ * num_probes_);
  std::vector<float> margins(bits_per_word_);
  for (size_t i = 0; i < n; ++i) {
    for (int t = 0; t < num_tables_; ++t) {
      uint32_t cell = 0;
      for (int b = 0; b < bits_per_word_; ++b) {
        const int r = t * bits_per_word_ + b;
        const float v = dots(static_cast<Eigen::Index>(i), r);
        cell |= static_cast<uint32_t>(v > 0.f) << b;
        margins[b] = std::abs(v) / row_norms_[r];
      }
      const uint32_t word = (static_cast<uint32_t>(t) << bits_per_word_) | cell;
      words.indexed[i * num_tables_ + t] = word;
      if (num_probes_ <= 1) continue;
      words.query.push_back(word);
      uint32_t masks[kMaxCellFlips];
      const int num_masks = NearestCellFlips(margins.data(), bits_per_word_, num_probes_, masks);
      for (int k = 0; k < num_masks; ++k) words.query.push_back(word ^ masks[k]);
    }
  }
  return words;
}

}  // namespace cashash
