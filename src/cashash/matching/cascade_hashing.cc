// Projections and hash codes of the Cascade Hashing definition in
// cascade_hashing.h. Hashing runs in exact integer arithmetic: the projection
// entries and the rounded mean are integers, so every backend gets the same
// bits whatever its precision or summation order.
#include "cashash/matching/cascade_hashing.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "cashash/matching/table_shape.h"

namespace cashash {
namespace {

uint64_t SplitMix64(uint64_t* state) {
  uint64_t z = (*state += 0x9E3779B97F4A7C15ull);
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
  return z ^ (z >> 31);
}

// round(64 * g) with g = (sum of 12 uniforms in [0, 2^32)) / 2^32 - 6
// (Irwin-Hall: mean 0, variance 1), clamped to [-255, 255].
int DrawProjectionEntry(uint64_t* state) {
  int64_t sum = 0;
  for (int i = 0; i < 12; ++i) sum += static_cast<int64_t>(SplitMix64(state) >> 32);
  const int64_t centred = sum - (int64_t{6} << 32);  // g * 2^32
  // 64 * g = centred / 2^26; round half away from zero.
  const int64_t half = int64_t{1} << 25;
  const int64_t magnitude = ((centred < 0 ? -centred : centred) + half) >> 26;
  const int64_t value = centred < 0 ? -magnitude : magnitude;
  return static_cast<int>(std::clamp<int64_t>(value, -255, 255));
}

// Integer rows when every entry is an integer in [-255, 255] (always the case
// for GenerateCascadeProjections); false for hand-made matrices.
bool IntegerRows(const std::vector<float>& matrix, std::vector<int16_t>* rows) {
  rows->resize(matrix.size());
  for (size_t i = 0; i < matrix.size(); ++i) {
    const float v = matrix[i];
    if (!(v >= -255.f && v <= 255.f) || v != std::round(v)) return false;
    (*rows)[i] = static_cast<int16_t>(v);
  }
  return true;
}

int RoundMeanEntry(float v) {
  return static_cast<int>(std::clamp(std::round(v), -32768.f, 32767.f));
}

}  // namespace

CascadeProjections GenerateCascadeProjections(const CasHashOptions& options) {
  const std::string error = options.Check();
  if (!error.empty()) throw std::invalid_argument(error);
  // Tables still at 0 (chosen per run, table_shape.h): the 8,192-feature shape.
  const TableShape shape = ChooseTableShape(0, options.num_tables, options.bits_per_table);
  CascadeProjections projections;
  projections.num_tables = shape.num_tables;
  projections.bits_per_table = shape.bits_per_table;
  projections.matrix.resize(static_cast<size_t>(projections.num_rows()) * kDescriptorDim);
  uint64_t state = options.random_seed;
  for (float& entry : projections.matrix) entry = static_cast<float>(DrawProjectionEntry(&state));
  return projections;
}

HashedFeatures HashDescriptors(const FeatureDescriptors& descriptors, size_t num_rows,
                               const CascadeProjections& projections, const MeanDescriptor& mean) {
  if (num_rows > descriptors.rows()) {
    throw std::invalid_argument("HashDescriptors: num_rows exceeds the descriptor rows");
  }
  const int num_bucket_rows = projections.num_bucket_rows();
  const int num_rows_total = projections.num_rows();
  if (projections.bits_per_table < 1 || projections.bits_per_table > 31 ||
      projections.matrix.size() != static_cast<size_t>(num_rows_total) * kDescriptorDim) {
    throw std::invalid_argument("HashDescriptors: projection matrix has the wrong shape");
  }

  HashedFeatures hashed;
  hashed.num_features = num_rows;
  hashed.num_tables = projections.num_tables;
  hashed.remap_codes.assign(2 * num_rows, 0);
  hashed.bucket_ids.assign(num_rows * projections.num_tables, 0);

  std::vector<int16_t> rows;
  const bool integer_rows = IntegerRows(projections.matrix, &rows);
  int32_t rounded_mean[kDescriptorDim];
  for (int d = 0; d < kDescriptorDim; ++d) rounded_mean[d] = RoundMeanEntry(mean[d]);

  // dot(row, desc - mean) > 0  <=>  dot(row, desc) > dot(row, mean).
  std::vector<int64_t> integer_offsets(num_rows_total, 0);
  std::vector<double> float_offsets(num_rows_total, 0.0);
  for (int j = 0; j < num_rows_total; ++j) {
    for (int d = 0; d < kDescriptorDim; ++d) {
      const size_t k = static_cast<size_t>(j) * kDescriptorDim + d;
      if (integer_rows) integer_offsets[j] += int64_t{rows[k]} * rounded_mean[d];
      float_offsets[j] += static_cast<double>(projections.matrix[k]) * rounded_mean[d];
    }
  }

  std::vector<uint8_t> bits(num_rows_total);
  for (size_t i = 0; i < num_rows; ++i) {
    const uint8_t* desc = descriptors.row(i);
    if (integer_rows) {
      int16_t x[kDescriptorDim];
      for (int d = 0; d < kDescriptorDim; ++d) x[d] = desc[d];
      for (int j = 0; j < num_rows_total; ++j) {
        const int16_t* row = rows.data() + static_cast<size_t>(j) * kDescriptorDim;
        int32_t dot = 0;
        for (int d = 0; d < kDescriptorDim; ++d) dot += int32_t{row[d]} * x[d];
        bits[j] = dot > integer_offsets[j];
      }
    } else {
      for (int j = 0; j < num_rows_total; ++j) {
        const float* row = projections.matrix.data() + static_cast<size_t>(j) * kDescriptorDim;
        double dot = 0.0;
        for (int d = 0; d < kDescriptorDim; ++d) dot += static_cast<double>(row[d]) * desc[d];
        bits[j] = dot > float_offsets[j];
      }
    }
    for (int t = 0; t < projections.num_tables; ++t) {
      uint32_t id = 0;
      for (int b = 0; b < projections.bits_per_table; ++b) {
        id |= static_cast<uint32_t>(bits[t * projections.bits_per_table + b]) << b;
      }
      hashed.bucket_ids[i * projections.num_tables + t] = id;
    }
    for (int b = 0; b < CasHashOptions::kRemapBits; ++b) {
      hashed.remap_codes[2 * i + b / 64] |= static_cast<uint64_t>(bits[num_bucket_rows + b])
                                            << (b % 64);
    }
  }
  return hashed;
}

}  // namespace cashash
