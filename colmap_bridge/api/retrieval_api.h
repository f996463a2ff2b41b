// Retrieval on a COLMAP database: which images look alike enough to be worth
// matching, from the cascade's own kind of hash codes (no vocabulary tree),
// and the matcher behind `cashash retrieval_matcher` / `vocab_tree_matcher`
// and Python's cashash.match_retrieval. docs/retrieval.md describes the
// method.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "cashash/base/types.h"
#include "cashash/retrieval/image_retrieval_index.h"
#include "cashash/retrieval/retrieval_options.h"
#include "colmap_bridge/api/matching_api.h"

namespace cashash {
namespace colmap {

// An index over images of a database; position i of the index is
// image_ids[i].
struct DatabaseRetrievalIndex {
  std::vector<image_t> image_ids;
  std::unique_ptr<ImageRetrievalIndex> index;
  int bits_per_word = 0;
  size_t features_indexed = 0;  // over all images
  // Wall seconds: the mean descriptor, reading and hashing every image
  // (one pass, on the options' threads), building the inverted file.
  double seconds_mean = 0;
  double seconds_reading_and_hashing = 0;
  double seconds_indexing = 0;
  // Processor seconds of all threads of the process over the same phases
  // (what a machine with fewer or busier cores would wait for).
  double cpu_seconds_reading_and_hashing = 0;
  double cpu_seconds_indexing = 0;
};

// Reads, hashes and indexes the given images of the database (all of table
// images when image_ids is empty), each image's first
// options.max_num_features features by scale (all with -1). Throws
// std::invalid_argument for bad options and std::runtime_error
// (DatabaseError included) for unusable input.
DatabaseRetrievalIndex BuildDatabaseRetrievalIndex(const std::string& database_path,
                                                   const RetrievalOptions& options,
                                                   std::vector<image_t> image_ids = {});

// The pairs retrieval chooses: each image with its options.num_images most
// similar images, as image ids (smaller first), each pair once, sorted.
struct RetrievedPairs {
  std::vector<ImagePair> pairs;
  double seconds_querying = 0;
  double cpu_seconds_querying = 0;
};
RetrievedPairs RetrievePairs(const DatabaseRetrievalIndex& index, const RetrievalOptions& options);

// Retrieves the pairs (RetrievePairs) and matches and verifies them as
// MatchPairs does; the summary's phases begin with the retrieval's.
// options.retrieval (VocabTreeMatching.*) says how; options.vocab_tree_path
// is accepted and ignored with a warning; with options.transitive_rounds >
// 0, the pairs the verified graph then implies are matched as well
// (AddTransitivePairs).
MatchingSummary MatchRetrieval(const std::string& database_path, const MatcherCommandOptions& options,
                               const MatchingCallbacks& callbacks = {});

}  // namespace colmap
}  // namespace cashash
