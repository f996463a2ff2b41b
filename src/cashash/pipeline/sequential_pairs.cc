#include "cashash/pipeline/sequential_pairs.h"

#include <algorithm>
#include <cstdlib>
#include <stdexcept>
#include <unordered_map>
#include <unordered_set>

#include "cashash/base/pair_id.h"

namespace cashash {
namespace {

// Collects pairs, each unordered pair once, in first-come order.
class PairCollector {
 public:
  void Add(image_t image_id1, image_t image_id2) {
    if (image_id1 == image_id2) return;
    if (seen_.insert(ImagePairToPairId(image_id1, image_id2)).second) pairs_.emplace_back(image_id1, image_id2);
  }
  std::vector<ImagePair> Take() { return std::move(pairs_); }

 private:
  std::vector<ImagePair> pairs_;
  std::unordered_set<pair_t> seen_;
};

// The images of each rig frame, and each image's frame and camera.
class RigFrames {
 public:
  RigFrames(const std::vector<SequenceImage>& images, bool expand) : expand_(expand) {
    for (const SequenceImage& image : images) {
      camera_of_.emplace(image.image_id, image.camera_id);
      if (!expand || image.frame_id == 0) continue;
      frame_of_.emplace(image.image_id, image.frame_id);
      images_of_[image.frame_id].push_back(image.image_id);
    }
    for (auto& [frame, ids] : images_of_) std::sort(ids.begin(), ids.end());
  }

  // The other images of the frame of `image_id` (none without rigs).
  const std::vector<image_t>& FrameImages(image_t image_id) const {
    static const std::vector<image_t> kNone;
    const auto frame = frame_of_.find(image_id);
    return frame == frame_of_.end() ? kNone : images_of_.at(frame->second);
  }

  // COLMAP's IsValidSequentialNeighbor: across frames of several images,
  // a neighbour must come from the same camera.
  bool ValidNeighbor(image_t image_id1, image_t image_id2) const {
    if (!expand_) return true;
    const auto frame1 = frame_of_.find(image_id1);
    const auto frame2 = frame_of_.find(image_id2);
    if (frame1 == frame_of_.end() || frame2 == frame_of_.end()) return true;
    if (images_of_.at(frame1->second).size() == 1 && images_of_.at(frame2->second).size() == 1) return true;
    return camera_of_.at(image_id1) == camera_of_.at(image_id2);
  }

 private:
  bool expand_;
  std::unordered_map<image_t, uint32_t> frame_of_;
  std::unordered_map<uint32_t, std::vector<image_t>> images_of_;
  std::unordered_map<image_t, camera_t> camera_of_;
};

}  // namespace

std::string SequentialPairingOptions::Check() const {
  if (overlap <= 0) return "--SequentialMatching.overlap must be > 0, got " + std::to_string(overlap);
  if (loop_detection_period <= 0) {
    return "--SequentialMatching.loop_detection_period must be > 0, got " + std::to_string(loop_detection_period);
  }
  if (loop_detection_num_images <= 0) {
    return "--SequentialMatching.loop_detection_num_images must be > 0, got " +
           std::to_string(loop_detection_num_images);
  }
  if (loop_detection_min_index_distance < 0) {
    return "--SequentialMatching.loop_detection_min_index_distance must be >= 0, got " +
           std::to_string(loop_detection_min_index_distance);
  }
  if (loop_detection_num_nearest_neighbors <= 0) {
    return "--SequentialMatching.loop_detection_num_nearest_neighbors must be > 0, got " +
           std::to_string(loop_detection_num_nearest_neighbors);
  }
  if (loop_detection_num_checks <= 0) {
    return "--SequentialMatching.loop_detection_num_checks must be > 0, got " +
           std::to_string(loop_detection_num_checks);
  }
  return "";
}

std::vector<image_t> OrderByName(std::vector<SequenceImage> images) {
  std::sort(images.begin(), images.end(),
            [](const SequenceImage& a, const SequenceImage& b) { return a.name < b.name; });
  std::vector<image_t> ids;
  ids.reserve(images.size());
  for (const SequenceImage& image : images) ids.push_back(image.image_id);
  return ids;
}

std::vector<ImagePair> SequentialPairs(const std::vector<SequenceImage>& images,
                                       const SequentialPairingOptions& options) {
  const std::vector<image_t> ordered = OrderByName(images);
  const RigFrames frames(images, options.expand_rig_images);
  PairCollector pairs;
  const size_t n = ordered.size();
  for (size_t index = 0; index < n; ++index) {
    const image_t image_id1 = ordered[index];
    for (image_t other : frames.FrameImages(image_id1)) pairs.Add(image_id1, other);
    for (int i = 0; i < options.overlap; ++i) {
      // 2^i places on: past 2^62 no collection has images left.
      if (options.quadratic_overlap && i >= 63) break;
      const size_t step = options.quadratic_overlap ? (size_t{1} << i) : static_cast<size_t>(i) + 1;
      if (step >= n - index) break;
      const image_t image_id2 = ordered[index + step];
      if (!frames.ValidNeighbor(image_id1, image_id2)) continue;
      pairs.Add(image_id1, image_id2);
      for (image_t other : frames.FrameImages(image_id2)) {
        if (other != image_id2) pairs.Add(image_id1, other);
      }
    }
  }
  return pairs.Take();
}

std::vector<image_t> LoopDetectionQueries(const std::vector<image_t>& ordered_ids,
                                          const SequentialPairingOptions& options) {
  std::vector<image_t> queries;
  const size_t period = static_cast<size_t>(std::max(1, options.loop_detection_period));
  for (size_t i = 0; i < ordered_ids.size(); i += period) queries.push_back(ordered_ids[i]);
  return queries;
}

int LoopDetectionRetrievalCount(const SequentialPairingOptions& options) {
  // Images closer than the minimum distance: d - 1 on either side.
  const int64_t near = 2 * std::max<int64_t>(0, int64_t{options.loop_detection_min_index_distance} - 1);
  return static_cast<int>(std::min<int64_t>(int64_t{options.loop_detection_num_images} + near, 1 << 30));
}

std::vector<ImagePair> LoopDetectionPairs(const std::vector<image_t>& ordered_ids,
                                          const std::vector<image_t>& queries,
                                          const std::vector<std::vector<image_t>>& retrieved,
                                          const SequentialPairingOptions& options) {
  if (queries.size() != retrieved.size()) {
    throw std::invalid_argument("loop detection: " + std::to_string(retrieved.size()) + " results for " +
                                std::to_string(queries.size()) + " queries");
  }
  std::unordered_map<image_t, int64_t> index_of;
  for (size_t i = 0; i < ordered_ids.size(); ++i) index_of.emplace(ordered_ids[i], static_cast<int64_t>(i));
  auto index = [&](image_t image_id) {
    const auto it = index_of.find(image_id);
    if (it == index_of.end()) {
      throw std::invalid_argument("loop detection: image id " + std::to_string(image_id) +
                                  " is not one of the sequence's images");
    }
    return it->second;
  };
  PairCollector pairs;
  for (size_t q = 0; q < queries.size(); ++q) {
    const int64_t query_index = index(queries[q]);
    int kept = 0;
    for (image_t candidate : retrieved[q]) {
      if (kept >= options.loop_detection_num_images) break;
      if (candidate == queries[q]) continue;
      const int64_t distance = std::abs(index(candidate) - query_index);
      if (distance < options.loop_detection_min_index_distance) continue;
      pairs.Add(queries[q], candidate);
      ++kept;
    }
  }
  return pairs.Take();
}

std::vector<ImagePair> AppendNewPairs(std::vector<ImagePair> first, const std::vector<ImagePair>& more) {
  PairCollector pairs;
  for (const ImagePair& pair : first) pairs.Add(pair.first, pair.second);
  for (const ImagePair& pair : more) pairs.Add(pair.first, pair.second);
  return pairs.Take();
}

}  // namespace cashash
