// Block and group sizes of the three-level scheduling from memory caps:
// blocks are what the matcher holds (device memory on the GPU), groups of
// blocks what the feature cache holds in host memory (see feature_cache.h
// and ScheduledPairChunks in pair_generation.h).
//
// What is held at once, and what the sizes are chosen for:
//   matcher:  the images of two consecutive chunks, at most 4 blocks (3 in
//             the scheduled order, 4 after resume removed pairs);
//   pipeline: features of the chunks in flight between its stages, at most
//             kPipelineBlocks blocks;
//   cache:    the current group pair and the next one's new group, 3 groups.
// Sizes use the largest image of the run, so no block or group can exceed
// its share whatever images fall into it.
#pragma once

#include <cstddef>
#include <string>
#include <vector>

namespace cashash {

// "4096" (MiB), "512M", "16G", "1.5G", "2T" (powers of 1024, case-blind,
// an optional trailing "B" or "iB"). False for anything else or zero.
bool ParseMemorySize(const std::string& text, size_t* bytes);
// "12.0 GiB", "512 MiB".
std::string FormatMemorySize(size_t bytes);
// Physical memory of this machine (0 when unknown).
size_t PhysicalMemoryBytes();

constexpr int kMatcherBlocks = 4;
// The loader's current and next chunk, six chunks queued for verification
// (PipelineOptions::chunks_in_queue), two being verified (the GPU
// verifier's default; the CPU's one), one waiting to be queued: 11 chunks
// of 2 blocks.
constexpr int kPipelineBlocks = 22;
constexpr int kCacheGroups = 3;
// Blocks are never made larger than COLMAP's default on their own: a chunk
// (block_size^2 pairs) is the unit of progress and of commits.
constexpr int kMaxDerivedBlockSize = 50;
// A group never holds more images than this, whatever the host cap leaves:
// a cross group pair matches a group's every image against the other's, so
// past a few thousand images a group's read (on the cache's loaders, beside
// the matching) costs little next to its pairs, while what the cache and the
// CPU matcher hold, three groups, would otherwise grow with the collection.
constexpr size_t kMaxGroupImages = 2000;

struct ScheduleLimits {
  size_t max_host_bytes = 0;
  // 0: the matcher keeps its images in host memory (CPU backend), which
  // then counts against max_host_bytes.
  size_t max_gpu_bytes = 0;
  // Share of max_gpu_bytes for the images the GPU matcher holds. The rest is
  // for everything else the run puts on the device under the same budget
  // (cuda/cashash_cuda/utils/gpu_resources.h): the matcher's batch buffers,
  // the exact rematch's kernels, the verifier's RANSAC buffers. Without
  // --max_gpu_memory (max_gpu_bytes the device's free memory, no budget)
  // the run uses kImageShareWithoutBudget.
  double gpu_image_share = 0.5;
  static constexpr double kImageShareWithoutBudget = 0.75;
  // No device budget: the GPU's blocks share slabs and keep their
  // quarter-step class (CachingBlockAllocator::SlabBlockClass) instead of
  // whole pages (SizeClass).
  bool gpu_without_budget = false;
  int block_size = 0;  // 0: derive, at most kMaxDerivedBlockSize
  int max_num_matches = 32768;  // rows per image the matcher keeps
  int num_tables = 8;           // cascade hash tables (matcher memory)
};

struct ScheduleSizes {
  int block_size = 0;
  int blocks_per_group = 0;
  size_t host_bytes_per_image = 0;     // features of the largest image
  size_t matcher_bytes_per_image = 0;  // what the matcher keeps of it (on the GPU: its block's size class)
  size_t predicted_host_bytes = 0;     // cache + pipeline + the matcher's images in use (on the GPU their host copies)
  size_t predicted_gpu_bytes = 0;      // images held by the GPU matcher
  // What the matcher may keep of images the pipeline has let go, so that
  // they are not hashed again (RetainingFeatureMatcher): the images in use
  // plus 80 % of what both caps leave over; on the CPU backend at most the
  // images of the groups the cache holds.
  size_t matcher_keep_bytes = 0;
  // Host memory of the images the matcher keeps beyond those in use, on top
  // of predicted_host_bytes and within max_host_bytes with it: on the GPU
  // the CPU fallback's copy of each kept image's descriptors, on the CPU the
  // kept images themselves. Printed with the schedule, so that a peak above
  // predicted_host_bytes is no surprise.
  size_t kept_host_bytes = 0;
  std::string warning;                 // set when a user block size exceeds the GPU cap
};

// Host bytes of one image's features (keypoints and descriptors).
size_t HostBytesPerImage(size_t num_features);
// What a cascade matcher keeps of one image (codes, bucket tables,
// descriptors), estimated from the GPU layout, the larger of the two backends.
size_t MatcherBytesPerImage(size_t num_features, int num_tables);

// Throws std::invalid_argument naming --max_host_memory when even blocks of
// two images in groups of one block do not fit.
ScheduleSizes ChooseScheduleSizes(const std::vector<size_t>& features_per_image, const ScheduleLimits& limits);

}  // namespace cashash
