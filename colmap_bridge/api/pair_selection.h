// The pairs of sequential_matcher and spatial_matcher, chosen from a
// database: the images, their rig frames and position priors read here, the
// rules applied by cashash/pipeline/sequential_pairs.h and spatial_pairs.h.
#pragma once

#include <memory>
#include <string>
#include <vector>

#include "cashash/pipeline/image_retrieval.h"
#include "colmap_bridge/api/command_options.h"
#include "colmap_bridge/api/retrieval_api.h"
#include "colmap_bridge/database.h"

namespace cashash {
namespace colmap {

struct SelectedPairs {
  std::vector<ImagePair> pairs;
  std::vector<std::string> notes;     // what was chosen, for the log
  std::vector<std::string> warnings;  // images left out, and why
};

// The retrieval for sequential loop detection when the caller brings none:
// image retrieval from the cascade's codes (retrieval_api.h), an index over
// `image_ids` (all images of the database when empty) built from the
// database's own descriptors with options.sequential's loop_detection_*
// settings, num_threads, and options.random_seed. Its queries run where
// the run matches (RetrievalDeviceForRun: the run's first GPU, else the
// CPU); `messages` get a line per call saying where and how long, and a
// warning where the GPU had no room. Throws as BuildDatabaseRetrievalIndex
// does.
std::unique_ptr<ImageRetrieval> CreateImageRetrievalForRun(const MatcherCommandOptions& options,
                                                           const std::string& database_path,
                                                           const std::vector<image_t>& image_ids = {},
                                                           RetrievalMessages messages = {});

// The message of a loop detection without a retrieval (a library caller's
// mistake), naming the option.
std::string LoopDetectionUnavailableMessage();

// COLMAP's sequential pairs of the images (options.sequential), plus the
// loop pairs `retrieval` finds when loop detection is on (retrieval must
// then not be null: std::invalid_argument otherwise).
SelectedPairs SelectSequentialPairs(const Database& database, const std::vector<Image>& images,
                                    const SequentialPairingOptions& options, ImageRetrieval* retrieval);

// COLMAP's spatial pairs of the images with a usable position prior
// (options.spatial). Images without one are named in a warning and left out,
// as COLMAP leaves them out; throws std::runtime_error naming the database
// and where priors were looked for when no image has one.
SelectedPairs SelectSpatialPairs(const Database& database, const std::vector<Image>& images,
                                 const SpatialPairingOptions& options);

}  // namespace colmap
}  // namespace cashash
