// The pairs of COLMAP's sequential_matcher: images ordered by name, each
// matched with the next `overlap` images (or the images 1, 2, 4, ...,
// 2^(overlap-1) places on with quadratic_overlap), rig frames expanded, and,
// with loop detection, every loop_detection_period-th image matched with the
// images most like it. Pure pair generation: the database and the
// retrieval that finds similar images live elsewhere (ImageRetrieval).
#pragma once

#include <string>
#include <vector>

#include "cashash/base/types.h"

namespace cashash {

// COLMAP's SequentialMatching.* options (SequentialPairingOptions of
// pycolmap), with its defaults.
struct SequentialPairingOptions {
  int overlap = 10;
  bool quadratic_overlap = true;
  // Match each image with the other images of its rig frame, and a
  // neighbour's frame as a whole (databases with rigs and frames only).
  bool expand_rig_images = true;
  bool loop_detection = false;
  // Every loop_detection_period-th image in name order (the first included)
  // is a loop query.
  int loop_detection_period = 10;
  // Images retrieved for each loop query.
  int loop_detection_num_images = 50;
  // Retrieved images fewer than this many places from the query in the
  // sequence are not loop pairs (0: no limit), so that the neighbours the
  // overlap matches anyway leave the retrieval's budget to real loops.
  int loop_detection_min_index_distance = 0;
  // COLMAP's vocabulary-tree settings of its loop detection, accepted so
  // that COLMAP command lines run; retrieval from the cascade's codes has
  // no tree and does not use them.
  int loop_detection_num_nearest_neighbors = 1;
  int loop_detection_num_checks = 64;
  int loop_detection_num_images_after_verification = 0;
  int loop_detection_max_num_features = -1;
  std::string vocab_tree_path;
  int num_threads = -1;

  // "" or a message naming the option (--SequentialMatching.name).
  std::string Check() const;
};

// One image of the sequence. frame_id 0: not part of a rig frame.
struct SequenceImage {
  image_t image_id = 0;
  std::string name;
  camera_t camera_id = 0;
  uint32_t frame_id = 0;
};

// Image ids sorted by name, byte by byte, as COLMAP orders them.
std::vector<image_t> OrderByName(std::vector<SequenceImage> images);

// The sequential pairs of `images` (any order; sorted by name here), without
// loop detection: for each image in name order, its frame's other images,
// then its sequential neighbours (each expanded to the neighbour's whole
// frame). Where images belong to frames of several images, only neighbours
// of the same camera count, so that the end of one camera's run is not the
// neighbour of the next camera's start. Each unordered pair once, in the
// order COLMAP first generates it, as (image, later image).
std::vector<ImagePair> SequentialPairs(const std::vector<SequenceImage>& images,
                                       const SequentialPairingOptions& options);

// The loop queries: every loop_detection_period-th id of `ordered_ids`,
// starting with the first.
std::vector<image_t> LoopDetectionQueries(const std::vector<image_t>& ordered_ids,
                                          const SequentialPairingOptions& options);

// How many images to ask the retrieval for per query so that, after the
// images closer than loop_detection_min_index_distance are dropped,
// loop_detection_num_images remain where the collection has them.
int LoopDetectionRetrievalCount(const SequentialPairingOptions& options);

// The loop pairs: (query, retrieved) for each query's retrieved images
// (most similar first) that are not the query itself and lie at least
// loop_detection_min_index_distance places away in `ordered_ids`, at most
// loop_detection_num_images per query. Throws std::invalid_argument naming
// an id that is not in `ordered_ids`.
std::vector<ImagePair> LoopDetectionPairs(const std::vector<image_t>& ordered_ids,
                                          const std::vector<image_t>& queries,
                                          const std::vector<std::vector<image_t>>& retrieved,
                                          const SequentialPairingOptions& options);

// `first` followed by the pairs of `more` that it lacks (either order), each
// unordered pair once.
std::vector<ImagePair> AppendNewPairs(std::vector<ImagePair> first, const std::vector<ImagePair>& more);

}  // namespace cashash
