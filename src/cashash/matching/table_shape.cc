#include "cashash/matching/table_shape.h"

#include <algorithm>
#include <cmath>
#include <sstream>

namespace cashash {
namespace {

double TargetCollisionProbability() {
  return TableCollisionProbability(kTableShapeReferenceTables, kTableShapeReferenceBits);
}

int MaxTablesForBits(int bits_per_table) {
  return std::max(1, std::min(kMaxShapeTables, kMaxSignatureBits / bits_per_table));
}

// The fewest tables of `bits_per_table` bits, at most max_tables, whose
// collision probability reaches the reference's. The small tolerance keeps
// 8 x 7 itself from rounding up to 9 tables.
int FewestTablesReachingReference(int bits_per_table, int max_tables) {
  const double target = TargetCollisionProbability();
  int tables = 1;
  while (tables < max_tables && TableCollisionProbability(tables, bits_per_table) < target - 1e-12) ++tables;
  return tables;
}

// The size a rule decides from: 0 (unknown) stands for the reference size.
size_t SizeOrReference(size_t features_per_image) {
  return features_per_image == 0 ? kTableShapeReferenceFeatures : features_per_image;
}

int FloorLog2(size_t n) {
  int log2_n = 0;
  for (; n > 1; n >>= 1) ++log2_n;
  return log2_n;
}

// One bit per doubling: floor(log2(n / 8192)) + 7, at least kMinShapeBits.
int BitsForSize(size_t features_per_image) {
  const int log2_n = FloorLog2(SizeOrReference(features_per_image));
  return std::max(kMinShapeBits, kTableShapeReferenceBits + log2_n - FloorLog2(kTableShapeReferenceFeatures));
}

// kBucketScreeningTables tables whose buckets hold about
// kBucketScreeningBucket features, within the signature's bits.
TableShape BucketScreeningShape(size_t features_per_image) {
  const int bits = FloorLog2(SizeOrReference(features_per_image) / kBucketScreeningBucket);
  TableShape shape;
  shape.num_tables = kBucketScreeningTables;
  shape.bits_per_table = std::min(bits, kBucketScreeningMaxBits);
  return shape;
}

// The CPU's recall shape from kCpuFineBucketFeatures: buckets of about
// kCpuFineBucket features, and the fewest tables that reach the reference's
// collision probability, without the GPU's limits.
TableShape CpuFineBucketShape(size_t features_per_image) {
  constexpr int kMaxCpuTables = 64;  // far above any size's need (22 at 32,768 features)
  TableShape shape;
  shape.bits_per_table = FloorLog2(SizeOrReference(features_per_image) / kCpuFineBucket);
  shape.num_tables = FewestTablesReachingReference(shape.bits_per_table, kMaxCpuTables);
  return shape;
}

// The recall shape for the size, with the bits chosen (bits_per_table 0).
TableShape ChooseRecallShape(size_t features_per_image, int num_tables) {
  TableShape shape;
  const double floor = TargetCollisionProbability() - kMaxCollisionLoss;
  int bits = BitsForSize(features_per_image);
  if (num_tables > 0) {
    bits = std::max(1, std::min(bits, kMaxSignatureBits / num_tables));
    while (bits > kTableShapeReferenceBits && TableCollisionProbability(num_tables, bits) < floor) --bits;
    shape.num_tables = num_tables;
    shape.bits_per_table = bits;
    return shape;
  }
  while (bits > kTableShapeReferenceBits && TableCollisionProbability(TablesForBits(bits), bits) < floor) --bits;
  shape.bits_per_table = bits;
  shape.num_tables = TablesForBits(bits);
  return shape;
}

}  // namespace

double TableCollisionProbability(int num_tables, int bits_per_table, double p) {
  return 1.0 - std::pow(1.0 - std::pow(p, bits_per_table), num_tables);
}

int TablesForBits(int bits_per_table) {
  return FewestTablesReachingReference(bits_per_table, MaxTablesForBits(bits_per_table));
}

TableShape ChooseTableShape(size_t features_per_image, int num_tables, int bits_per_table, TableShapeGoal goal,
                            TableShapeBackend backend) {
  if (IsCpuFineBucketShape(features_per_image, num_tables, bits_per_table, goal, backend)) {
    return CpuFineBucketShape(features_per_image);
  }
  TableShape shape;
  if (num_tables > 0 && bits_per_table > 0) {
    shape.num_tables = num_tables;
    shape.bits_per_table = bits_per_table;
    return shape;
  }
  if (bits_per_table > 0) {
    shape.bits_per_table = bits_per_table;
    shape.num_tables = TablesForBits(bits_per_table);
    return shape;
  }
  if (IsBucketScreeningShape(features_per_image, num_tables, bits_per_table, goal)) {
    return BucketScreeningShape(features_per_image);
  }
  shape = ChooseRecallShape(features_per_image, num_tables);
  if (goal != TableShapeGoal::kScreening) return shape;
  const int bits = shape.bits_per_table + 1;
  const int tables = num_tables > 0 ? num_tables : TablesForBits(bits);
  if (tables * bits <= kMaxSignatureBits && TableCollisionProbability(tables, bits) >= kScreeningCollisionFloor) {
    shape.num_tables = tables;
    shape.bits_per_table = bits;
  }
  return shape;
}

bool IsBucketScreeningShape(size_t features_per_image, int num_tables, int bits_per_table, TableShapeGoal goal) {
  return goal == TableShapeGoal::kScreening && num_tables == 0 && bits_per_table == 0 &&
         SizeOrReference(features_per_image) >= kBucketScreeningFeatures;
}

bool IsCpuFineBucketShape(size_t features_per_image, int num_tables, int bits_per_table, TableShapeGoal goal,
                          TableShapeBackend backend) {
  return backend == TableShapeBackend::kCpu && goal == TableShapeGoal::kRecall && num_tables == 0 &&
         bits_per_table == 0 && SizeOrReference(features_per_image) >= kCpuFineBucketFeatures;
}

size_t TypicalFeatureCount(std::vector<size_t> rows_per_image, int max_num_matches) {
  if (rows_per_image.empty()) return 0;
  const size_t cap = static_cast<size_t>(std::max(1, max_num_matches));
  for (size_t& rows : rows_per_image) rows = std::min(rows, cap);
  const size_t middle = rows_per_image.size() / 2;
  std::nth_element(rows_per_image.begin(), rows_per_image.begin() + middle, rows_per_image.end());
  return rows_per_image[middle];
}

CasHashOptions ResolveTableShape(const CasHashOptions& options, size_t features_per_image, TableShapeGoal goal,
                                 TableShapeBackend backend) {
  CasHashOptions resolved = options;
  const TableShape shape =
      ChooseTableShape(features_per_image, options.num_tables, options.bits_per_table, goal, backend);
  resolved.num_tables = shape.num_tables;
  resolved.bits_per_table = shape.bits_per_table;
  return resolved;
}

std::string DescribeTableShape(const CasHashOptions& requested, const CasHashOptions& resolved,
                               size_t features_per_image, size_t num_images, TableShapeGoal goal,
                               TableShapeBackend backend) {
  std::ostringstream text;
  text << "Hash tables: " << resolved.num_tables << " x " << resolved.bits_per_table << " bits";
  if (requested.num_tables > 0 && requested.bits_per_table > 0) {
    text << " (as set by the options)";
    return text.str();
  }
  text << " (";
  if (requested.num_tables > 0) text << "tables as set, bits ";
  if (requested.bits_per_table > 0) text << "bits as set, tables ";
  text << "chosen for " << features_per_image << " features per image, the median of " << num_images << " image"
       << (num_images == 1 ? "" : "s");
  if (IsCpuFineBucketShape(features_per_image, requested.num_tables, requested.bits_per_table, goal, backend)) {
    text << ", buckets of about " << kCpuFineBucket << " features on the CPU";
  }
  if (goal == TableShapeGoal::kScreening && requested.bits_per_table == 0) {
    if (IsBucketScreeningShape(features_per_image, requested.num_tables, requested.bits_per_table, goal)) {
      text << ", buckets of about " << kBucketScreeningBucket << " features: the exact rematch decides";
    } else {
      text << ", a bit more than for recall: the exact rematch decides";
    }
  }
  text << ")";
  return text.str();
}

}  // namespace cashash
