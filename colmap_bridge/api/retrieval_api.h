// Retrieval on a COLMAP database: which images look alike enough to be worth
// matching, from the cascade's own kind of hash codes (no vocabulary tree),
// and the matcher behind `cashash retrieval_matcher` / `vocab_tree_matcher`
// and Python's cashash.match_retrieval. docs/retrieval.md describes the
// method.
#pragma once

#include <cstdint>
#include <functional>
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

// Where a retrieval tells what it did: lines of information, warnings.
struct RetrievalMessages {
  std::function<void(const std::string&)> info;
  std::function<void(const std::string&)> warning;
};

// Where retrieval's queries run: a GPU, within a budget of its memory, or
// the CPU (the index's threads).
struct RetrievalDevice {
  int gpu_index = -1;              // -1: the CPU
  size_t memory_budget_bytes = 0;  // --max_gpu_memory; 0: none but the device's own
};

// The device of a run of `options`: the first GPU the run matches on
// (ChooseRunDevices: --FeatureMatching.use_gpu and gpu_index, a usable
// device of a CUDA build), the CPU otherwise. Throws std::invalid_argument
// for a malformed gpu_index or max_gpu_memory.
RetrievalDevice RetrievalDeviceForRun(const MatcherCommandOptions& options);

// The best k neighbours of each of `images` (positions of the index, in
// that order; every image where null), found on `device`; where that GPU
// has no room for the index (DeviceMemoryError) or the build has no CUDA,
// on the CPU, and gpu_fallback says why.
struct NeighborSearch {
  std::vector<std::vector<RetrievalNeighbor>> neighbors;
  int gpu_index = -1;        // where the search ran; -1: the CPU
  std::string gpu_fallback;  // why a GPU search ran on the CPU; empty otherwise
};
NeighborSearch SearchNeighbors(const ImageRetrievalIndex& index, const std::vector<uint32_t>* images, size_t k,
                               const RetrievalDevice& device);

// "on GPU 0", "on the CPU": where a search ran, for the log.
std::string SearchPlace(int gpu_index);

// The pairs retrieval chooses: each image with its options.num_images most
// similar images, as image ids (smaller first), each pair once, sorted.
// The queries run on `device` (SearchNeighbors).
struct RetrievedPairs {
  std::vector<ImagePair> pairs;
  double seconds_querying = 0;
  double cpu_seconds_querying = 0;
  int gpu_index = -1;        // where the queries ran; -1: the CPU
  std::string gpu_fallback;  // why they ran on the CPU although a GPU was asked for
};
RetrievedPairs RetrievePairs(const DatabaseRetrievalIndex& index, const RetrievalOptions& options,
                             const RetrievalDevice& device = {});

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
