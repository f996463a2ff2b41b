// The GPU's TopK over an ImageRetrievalIndex (cashash/retrieval/
// image_retrieval_index.h): the same neighbours, found on the device. The
// index's postings stay on the device for the call; the query vectors go up
// in batches of query images; one thread block per query image (and tile of
// images, below) adds the query's postings into a shared-memory
// accumulator of every image's score and keeps the best k by the CPU's rule
// (RanksBefore: score descending, then position ascending; the query
// itself and images sharing no word with it are never returned).
//
// Deterministic: each term (query weight x posting weight, a float product)
// is rounded once to a whole number of kGpuRetrievalScoreStep, at least one
// (so an image sharing a word never scores 0), and the terms are added as
// 32-bit integers, so a score does not depend on the order in which the
// threads add them: the same neighbours on every run and device. A score
// then differs from the exact sum by at most half a step per shared word,
// and the CPU's float sum differs from it by its own rounding: two images
// whose CPU scores are that close may rank the other way round.
//
// Tiles: the accumulator holds one 32-bit score per image; where the
// images outnumber what a block's shared memory holds (about 57,800 on an
// H100 or H200), the images are cut into tiles, each block keeps its tile's best
// k, and the tiles' lists are merged on the host.
//
// Memory: the postings (8 bytes each), the word offsets (8 bytes per word of
// the vocabulary) and one batch of query vectors and results (at most 256 MiB),
// all taken from `resources` under its budget (--max_gpu_memory). Where
// they do not fit, DeviceMemoryError is thrown and the caller searches on
// the CPU.
//
// Plain C++ header (the bridge includes it under CASHASH_WITH_CUDA).
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include "cashash/retrieval/image_retrieval_index.h"
#include "cashash_cuda/utils/gpu_resources.h"

namespace cashash {
namespace cuda {

// The unit of the GPU's fixed-point scores: 2^-31 (a cosine, at most 1,
// then fits 32 bits with room for the rounding of every term).
constexpr double kGpuRetrievalScoreStep = 1.0 / 2147483648.0;

struct GpuRetrievalConfig {
  // The owner of the device's memory: its device runs the search, its
  // budget bounds what the search takes. Required.
  GpuResources* resources = nullptr;
  // Most images one block scores at once; 0: as many as the device's
  // shared memory per block holds. Smaller values cut the images into
  // more tiles (tests use it to reach the tiles on small indexes).
  size_t max_images_per_tile = 0;
};

// What one search did, for logs and benchmarks.
struct GpuRetrievalStats {
  size_t resident_bytes = 0;  // postings and word offsets
  size_t batches = 0;
  size_t tiles = 0;  // image tiles per query
};

// TopK(image, k) of ImageRetrievalIndex for each of `query_images`
// (positions of the index), in that order. Throws DeviceMemoryError where
// the device (or the budget) has no room, std::out_of_range for a position
// past the index, std::runtime_error for other CUDA failures.
std::vector<std::vector<RetrievalNeighbor>> GpuTopK(const RetrievalIndexView& index,
                                                    const std::vector<uint32_t>& query_images, size_t k,
                                                    const GpuRetrievalConfig& config,
                                                    GpuRetrievalStats* stats = nullptr);

// AllTopK(k): GpuTopK of every image of the index.
std::vector<std::vector<RetrievalNeighbor>> GpuAllTopK(const RetrievalIndexView& index, size_t k,
                                                       const GpuRetrievalConfig& config,
                                                       GpuRetrievalStats* stats = nullptr);

// The device bytes a search keeps for the whole call (postings and word
// offsets), before the batches' own.
size_t GpuRetrievalResidentBytes(const RetrievalIndexView& index);

}  // namespace cuda
}  // namespace cashash
