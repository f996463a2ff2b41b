// How many first-level hash tables, and how many bits each, the cascade uses
// for images of a given size (--CasHash.num_tables / --CasHash.bits_per_table
// left at 0). docs/cascade_parameters.md, "Tables that grow with the images",
// has the derivation and the measurements.
//
// A table of b bits cuts n features into 2^b buckets of about n / 2^b, and a
// query visits its bucket in each of L tables: about L n / 2^b candidates. At
// a fixed shape that grows with n, so the cascade's cost per pair grows as
// n^2, like brute force. One more bit per doubling of n from 16,384 on keeps
// the buckets, and so the candidates per query, the same size. Below 8,192
// features the bits stay at 7: fewer bits with fewer tables hold the same
// collision probability but visit more candidates (generated streets, 2,048
// features: 6 x 5 visits 441 bucket entries per query for recall 0.983,
// 8 x 7 175 for 0.976, 1.7x faster).
//
// A true match whose projection bit agrees with the query's with
// probability p lands in the query's bucket of one table with p^b, of at
// least one of L tables with 1 - (1 - p^b)^L. p = 0.867 fits the recall of
// eight (L, b) settings measured on fountain-P11; the rule keeps this
// collision probability at the default's (8 x 7 at 8,192 features: 0.975)
// by choosing, for each b, the fewest tables that reach it.
//
// The GPU backend packs the bucket bits of a feature in one 64-bit word
// (L b <= 64) and runs at most 32 tables. Past 8 bits no L within 64 bits
// reaches the target (8 x 8: 0.954, 7 x 9: 0.897), so the bits stop at the
// width whose capped L loses at most kMaxCollisionLoss; beyond that size the
// candidates per query grow again (linearly in n), the recall does not drop.
// Shapes within these limits (TableShapeBackend::kAny) are matched
// identically by the CPU and the GPU. A run resolved for the CPU takes,
// from kCpuFineBucketFeatures on, a recall shape past them (kCpu): its
// matches then differ from the GPU's.
#pragma once

#include <cstddef>
#include <string>
#include <vector>

#include "cashash/matching/matching_options.h"

namespace cashash {

struct TableShape {
  int num_tables = 0;
  int bits_per_table = 0;
};

// Features per image at which the rule gives today's defaults, 8 x 7.
constexpr size_t kTableShapeReferenceFeatures = 8192;
constexpr int kTableShapeReferenceTables = 8;
constexpr int kTableShapeReferenceBits = 7;
// Probability that one projection bit of a true match agrees with the query's.
constexpr double kTableShapeBitAgreement = 0.867;
// Largest drop of the collision probability below the default's accepted to
// add a bit when the 64-bit signature caps the number of tables.
constexpr double kMaxCollisionLoss = 0.025;
// Limits of the GPU backend (cuda/cashash_cuda/matching/cascade_hashing.cuh,
// cascade_matcher.cuh), kept on every backend.
constexpr int kMaxSignatureBits = 64;
constexpr int kMaxShapeTables = 32;
// Fewest bits the rule chooses: the reference's (8 x 7 for every smaller image).
constexpr int kMinShapeBits = kTableShapeReferenceBits;
// Lowest collision probability of a screening shape below
// kBucketScreeningFeatures (TableShapeGoal): admits 8 x 8 (0.954).
constexpr double kScreeningCollisionFloor = 0.89;
// From this size on a screening shape is kBucketScreeningTables tables whose
// buckets hold kBucketScreeningBucket features or up to twice as many (bits
// = floor(log2(n / 16)), at most kBucketScreeningMaxBits): 3 x 8 from 4,096
// features, 3 x 9 from 8,192, 3 x 10 from 16,384; 48-96 candidates per
// query up to 32,767 features, where 8 x 8 visits 128-256. Real extractions
// capped at 8,192 have medians of 5,000-7,200 features, so the rule starts
// where their buckets first reach 16 features.
constexpr size_t kBucketScreeningFeatures = 4096;
constexpr int kBucketScreeningTables = 3;
constexpr size_t kBucketScreeningBucket = 16;
// The widest bucket screening tables: the largest width measured (16,384
// features). Beyond it the buckets, and the candidates per query, grow with
// n instead of the screen's collision probability falling further.
constexpr int kBucketScreeningMaxBits = 10;
static_assert(kBucketScreeningTables * kBucketScreeningMaxBits <= kMaxSignatureBits,
              "the bucket screening tables must fit the GPU's 64-bit bucket signature");
// Cascade matches a pair needs for the exact rematch when the bucket
// screening shape was chosen and the threshold was not set
// (--CasHash.exact_rematch_min_matches; the runs' default is 12 for every
// other shape). Three tables find about 0.62 / 0.86 of what six found
// (TableCollisionProbability at 9 bits), so 12 scales to about 8.7; 8 is
// the measured one: on both kinds of street, on the CPU and on the GPU, it
// kept brute force's verified pairs (docs/cascade_parameters.md, "Fewer
// screening tables").
constexpr int kBucketScreeningRematchMinMatches = 8;

// What the cascade's matches are for. kRecall: they are the run's matches
// (guided matching, no exact rematch), so the shape holds the reference's
// collision probability. kScreening: the exact rematch decides which pairs
// may verify and gives their matches, so the cascade only has to find its
// threshold of matches on the pairs that verify. Below 4,096 features the
// shape takes one bit more than kRecall's (half the candidates per query)
// while its collision probability stays at kScreeningCollisionFloor or
// above; from 4,096 on, 3 tables of buckets of 16-31 features
// (kBucketScreeningFeatures). CascadeOnlyScreens says which goal a run has.
// The screening shapes keep brute force's verified pairs and inlier matches
// on generated streets and the real sets while the cascade's matching time
// falls. Buckets of at least 16 features because at 2,048 features smaller
// buckets were slower (more buckets per pair). Three tables need the
// rematch from 8 matches (kBucketScreeningRematchMinMatches): from 12, six
// tables lost 1-2 verified pairs on noisy streets, three from 8 none
// (docs/cascade_parameters.md, "Fewer screening tables").
enum class TableShapeGoal { kRecall, kScreening };

// Which backend will match with the shape. kAny: shapes the GPU can run
// (a 64-bit bucket signature, at most 32 tables), which the CPU matches
// identically; the default wherever the backend is not known. kCpu: the
// CPU, which has neither limit (kCpuFineBucketFeatures).
enum class TableShapeBackend { kAny, kCpu };

// On the CPU, from this size on, the recall shape has buckets of about
// kCpuFineBucket features: bits = log2(n / kCpuFineBucket) and the fewest
// tables that hold the reference's collision probability (19 x 12 at
// 16,384 features, 22 x 13 at 32,768). Why: the CPU's bucket scan costs
// about one table lookup per 26 bucket entries visited, and the 64-bit
// signature leaves 8 x 8 at 16,384 features, whose 512 entries a query
// (twice 4,096 features' 8 x 7) made 4x the features cost 7.9x the
// matching time. Of the shapes at the reference's collision probability
// (8 x 8, 12 x 9, 14 x 10, 16 x 11, 19 x 12, 24 x 13) on a 16-image street
// of 16,384 features, 19 x 12 was the fastest: 5.9x the time of 4,096
// features, at 0.985 of brute force's raw matches (8 x 8: 0.974)
// (docs/cpu_matching.md, "Linear cost in the features"). Such a run's
// matches differ from the GPU's, which keeps 8 x 8.
constexpr size_t kCpuFineBucketFeatures = 16384;
constexpr size_t kCpuFineBucket = 4;

// 1 - (1 - p^bits)^tables.
double TableCollisionProbability(int num_tables, int bits_per_table, double p = kTableShapeBitAgreement);

// The fewest tables of `bits_per_table` bits whose collision probability
// reaches the default's, within the GPU limits.
int TablesForBits(int bits_per_table);

// The shape for images of `features_per_image` features (0: the reference
// size). num_tables / bits_per_table > 0 are kept as given (explicit
// options win) and the other is chosen for them: bits from the size and
// within 64 / num_tables; tables from the bits.
// An explicit bits_per_table is never changed by the goal.
TableShape ChooseTableShape(size_t features_per_image, int num_tables = 0, int bits_per_table = 0,
                            TableShapeGoal goal = TableShapeGoal::kRecall,
                            TableShapeBackend backend = TableShapeBackend::kAny);

// Whether ChooseTableShape gives the CPU's fine-bucket recall shape
// (kCpuFineBucketFeatures) for these options.
bool IsCpuFineBucketShape(size_t features_per_image, int num_tables, int bits_per_table, TableShapeGoal goal,
                          TableShapeBackend backend);

// The feature count a run's rule is decided from: the median over its
// images of min(rows, max_num_matches) (the upper one of the two middle
// values; 0 for no images).
size_t TypicalFeatureCount(std::vector<size_t> rows_per_image, int max_num_matches);

// Whether ChooseTableShape gives the bucket screening shape for these
// options (goal kScreening, tables and bits both left at 0, at least
// kBucketScreeningFeatures features): the shape whose rematch threshold is
// kBucketScreeningRematchMinMatches.
bool IsBucketScreeningShape(size_t features_per_image, int num_tables, int bits_per_table, TableShapeGoal goal);

// `options` with num_tables and bits_per_table chosen for the size where
// they are 0 (the defaults), unchanged where set.
CasHashOptions ResolveTableShape(const CasHashOptions& options, size_t features_per_image,
                                 TableShapeGoal goal = TableShapeGoal::kRecall,
                                 TableShapeBackend backend = TableShapeBackend::kAny);

// One line for the run's log, e.g. "Hash tables: 8 x 8 bits (chosen for
// 16384 features per image, the median of 300 images)".
std::string DescribeTableShape(const CasHashOptions& requested, const CasHashOptions& resolved,
                               size_t features_per_image, size_t num_images,
                               TableShapeGoal goal = TableShapeGoal::kRecall,
                               TableShapeBackend backend = TableShapeBackend::kAny);

}  // namespace cashash
