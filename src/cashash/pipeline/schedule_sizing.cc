#include "cashash/pipeline/schedule_sizing.h"

#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <stdexcept>

#include "cashash/base/caching_block_allocator.h"
#include "cashash/base/types.h"

namespace cashash {

bool ParseMemorySize(const std::string& text, size_t* bytes) {
  size_t end = 0;
  double value = 0;
  try {
    value = std::stod(text, &end);
  } catch (const std::exception&) {
    return false;
  }
  std::string unit;
  for (size_t i = end; i < text.size(); ++i) unit += static_cast<char>(std::toupper(text[i]));
  if (unit.size() > 1 && unit.back() == 'B') unit.pop_back();  // "GB" / "GIB"
  if (unit.size() > 1 && unit.back() == 'I') unit.pop_back();
  double scale = 0;
  if (unit.empty() || unit == "M") {
    scale = 1024.0 * 1024.0;  // plain numbers are MiB, as --max_gpu_memory on the GPU
  } else if (unit == "K") {
    scale = 1024.0;
  } else if (unit == "G") {
    scale = 1024.0 * 1024.0 * 1024.0;
  } else if (unit == "T") {
    scale = 1024.0 * 1024.0 * 1024.0 * 1024.0;
  } else {
    return false;
  }
  const double result = value * scale;
  if (!(result >= 1.0) || result > 1e18) return false;
  *bytes = static_cast<size_t>(result);
  return true;
}

std::string FormatMemorySize(size_t bytes) {
  char text[32];
  if (bytes >= (size_t{1} << 30)) {
    std::snprintf(text, sizeof(text), "%.1f GiB", bytes / double(size_t{1} << 30));
  } else {
    std::snprintf(text, sizeof(text), "%zu MiB", (bytes + (size_t{1} << 20) - 1) >> 20);
  }
  return text;
}

size_t PhysicalMemoryBytes() {
  const long pages = sysconf(_SC_PHYS_PAGES);
  const long page_size = sysconf(_SC_PAGE_SIZE);
  if (pages <= 0 || page_size <= 0) return 0;
  return static_cast<size_t>(pages) * static_cast<size_t>(page_size);
}

size_t HostBytesPerImage(size_t num_features) {
  return num_features * (kDescriptorDim + sizeof(Keypoint)) + 1024;
}

size_t MatcherBytesPerImage(size_t num_features, int num_tables) {
  // Descriptors, 64-bit signature, 128-bit code, and one 32-byte bucket
  // entry per table per feature (cuda/cashash_cuda/matching/device_image.cuh); bucket
  // offsets of up to 10-bit tables and alignment on top.
  const size_t per_feature = kDescriptorDim + 8 + 16 + 32 * static_cast<size_t>(num_tables);
  const size_t per_image = static_cast<size_t>(num_tables) * 2 * 1025 * 4 + 8 * 256;
  return num_features * per_feature + per_image;
}

// One function because block size, blocks per group and the matcher's keep
// budget are derived in turn from the same caps through the fixed_host and
// group_bytes lambdas, each step reading the one before.
ScheduleSizes ChooseScheduleSizes(const std::vector<size_t>& features_per_image, const ScheduleLimits& limits) {
  ScheduleSizes sizes;
  size_t largest = 1;
  for (size_t f : features_per_image) largest = std::max(largest, f);
  sizes.host_bytes_per_image = HostBytesPerImage(largest);
  const bool gpu = limits.max_gpu_bytes > 0;
  sizes.matcher_bytes_per_image =
      MatcherBytesPerImage(std::min(largest, static_cast<size_t>(std::max(1, limits.max_num_matches))),
                           limits.num_tables);
  // On the GPU an image's block is rounded up to its size class, and that
  // is what the device's owner of memory counts against the budget.
  if (gpu) {
    sizes.matcher_bytes_per_image = limits.gpu_without_budget
                                        ? CachingBlockAllocator::SlabBlockClass(sizes.matcher_bytes_per_image)
                                        : CachingBlockAllocator::SizeClass(sizes.matcher_bytes_per_image);
  }
  const size_t gpu_for_images = static_cast<size_t>(limits.gpu_image_share * limits.max_gpu_bytes);
  const size_t n = std::max<size_t>(2, features_per_image.size());

  // Nothing holds more images than the run has.
  const size_t num_images = features_per_image.size();
  auto images = [num_images](size_t count) { return std::min(count, num_images); };
  // What the host keeps of an image the GPU matcher holds: the copy of its
  // descriptors that the CPU fallback matches from (a third of the device
  // layout at 8 tables).
  const size_t host_copy =
      std::min(largest, static_cast<size_t>(std::max(1, limits.max_num_matches))) * kDescriptorDim + 1024;
  // Host bytes besides the cache for blocks of bs images: the pipeline's, and
  // the matcher's images in use (on the GPU their host copies).
  auto fixed_host = [&](size_t bs) {
    return images(kPipelineBlocks * bs) * sizes.host_bytes_per_image +
           images(kMatcherBlocks * bs) * (gpu ? host_copy : sizes.matcher_bytes_per_image);
  };
  // The cache with groups of one block.
  auto group_bytes = [&](size_t bs) { return images(kCacheGroups * bs) * sizes.host_bytes_per_image; };

  size_t bs = 0;
  if (limits.block_size > 0) {
    bs = static_cast<size_t>(limits.block_size);
    if (gpu && kMatcherBlocks * bs * sizes.matcher_bytes_per_image > gpu_for_images) {
      sizes.warning = "blocks of " + std::to_string(bs) + " images of up to " + std::to_string(largest) +
                      " features need about " + FormatMemorySize(kMatcherBlocks * bs * sizes.matcher_bytes_per_image) +
                      " of GPU memory, more than the " + FormatMemorySize(gpu_for_images) + " that --max_gpu_memory " +
                      FormatMemorySize(limits.max_gpu_bytes) + " leaves for images";
    }
  } else {
    bs = std::min<size_t>(kMaxDerivedBlockSize, n);
    if (gpu) bs = std::min(bs, gpu_for_images / (kMatcherBlocks * sizes.matcher_bytes_per_image));
    while (bs > 2 && fixed_host(bs) + group_bytes(bs) > limits.max_host_bytes) --bs;
    if (bs < 2) {
      bs = 2;
      sizes.warning = "--max_gpu_memory " + FormatMemorySize(limits.max_gpu_bytes) + " cannot hold " +
                      std::to_string(kMatcherBlocks * 2) + " images of " + std::to_string(largest) +
                      " features; matching in blocks of 2 images anyway";
    }
  }
  if (fixed_host(bs) + group_bytes(bs) > limits.max_host_bytes) {
    throw std::invalid_argument("--max_host_memory " + FormatMemorySize(limits.max_host_bytes) +
                                " is too small: blocks of " + std::to_string(bs) + " images of up to " +
                                std::to_string(largest) + " features need at least " +
                                FormatMemorySize(fixed_host(bs) + group_bytes(bs)));
  }
  const size_t num_blocks = std::max<size_t>(1, (num_images + bs - 1) / bs);
  const size_t cache_bytes = limits.max_host_bytes - fixed_host(bs);
  size_t per_group = 1;
  if (images(num_blocks * bs) * sizes.host_bytes_per_image <= cache_bytes) {
    per_group = num_blocks;  // every image fits: one group, each image read once
  } else {
    per_group = std::max<size_t>(1, cache_bytes / (kCacheGroups * bs * sizes.host_bytes_per_image));
  }
  per_group = std::min(per_group, std::max<size_t>(1, kMaxGroupImages / bs));
  sizes.block_size = static_cast<int>(bs);
  sizes.blocks_per_group = static_cast<int>(std::min(per_group, num_blocks));
  sizes.predicted_host_bytes =
      fixed_host(bs) + images(kCacheGroups * sizes.blocks_per_group * bs) * sizes.host_bytes_per_image;
  sizes.predicted_gpu_bytes = gpu ? images(kMatcherBlocks * bs) * sizes.matcher_bytes_per_image : 0;
  // Kept images cost matcher memory: on the CPU backend host memory; on the
  // GPU device memory, plus on the host only the copy of their descriptors
  // that the CPU fallback keeps (host_copy).
  // Counting the device layout against host memory too (as before) kept
  // 2.7k of 5000 images of 8192 features under --max_host_memory 16G, and
  // the block order then re-hashed nearly every image for every block pair
  // (184k hashings in 9.6M pairs, 41 % of the run on an H200).
  const size_t in_use_images = images(kMatcherBlocks * bs);
  const size_t in_use = in_use_images * sizes.matcher_bytes_per_image;
  const size_t host_left = limits.max_host_bytes - std::min(limits.max_host_bytes, sizes.predicted_host_bytes);
  size_t keep_images = 0;
  if (gpu) {
    const size_t gpu_left = gpu_for_images - std::min(gpu_for_images, in_use);
    keep_images = std::min(host_left / host_copy, gpu_left / sizes.matcher_bytes_per_image);
  } else {
    // An image beyond the cache's groups comes back only with its group, after
    // a whole group pair of matching; hashing it again then costs little
    // beside that, and keeping it would cost host memory for every image of
    // the collection.
    const size_t cache_images = images(kCacheGroups * static_cast<size_t>(sizes.blocks_per_group) * bs);
    keep_images = std::min(host_left / sizes.matcher_bytes_per_image, cache_images);
  }
  sizes.matcher_keep_bytes =
      in_use + static_cast<size_t>(0.8 * static_cast<double>(keep_images * sizes.matcher_bytes_per_image));
  // What the kept images beyond those in use (which predicted_host_bytes
  // counts) hold on the host.
  const size_t kept_images =
      std::min(static_cast<size_t>(0.8 * static_cast<double>(keep_images)), num_images - in_use_images);
  sizes.kept_host_bytes = kept_images * (gpu ? host_copy : sizes.matcher_bytes_per_image);
  return sizes;
}

}  // namespace cashash
