#include "colmap_bridge/api/pair_selection.h"

#include <algorithm>
#include <chrono>
#include <sstream>
#include <stdexcept>
#include <unordered_map>
#include <utility>

#include "cashash/pipeline/sequential_pairs.h"
#include "cashash/pipeline/spatial_pairs.h"
#include "cashash/retrieval/retrieval_options.h"
#include "colmap_bridge/api/retrieval_api.h"
#include "colmap_bridge/image_frames.h"
#include "colmap_bridge/position_priors.h"

namespace cashash {
namespace colmap {
namespace {

// Names listed in one warning; the rest are counted.
constexpr size_t kNamesListed = 10;

// "a.jpg, b.jpg and 3 more".
std::string NameList(const std::vector<std::string>& names) {
  std::string text;
  for (size_t i = 0; i < names.size() && i < kNamesListed; ++i) {
    if (i > 0) text += ", ";
    text += names[i];
  }
  if (names.size() > kNamesListed) text += " and " + std::to_string(names.size() - kNamesListed) + " more";
  return text;
}

std::string Plural(size_t count, const std::string& noun) {
  return std::to_string(count) + " " + noun + (count == 1 ? "" : "s");
}

// "1 image has", "3 images have".
std::string ImagesHave(size_t count) { return Plural(count, "image") + (count == 1 ? " has" : " have"); }

// Loop detection's retrieval: an index over the run's images built from
// the database's own descriptors (retrieval_api.h), asked for all queries
// of a call at once on the run's device (SearchNeighbors: its first GPU,
// else the CPU's threads).
class DatabaseImageRetrieval : public ImageRetrieval {
 public:
  DatabaseImageRetrieval(DatabaseRetrievalIndex index, RetrievalDevice device, RetrievalMessages messages)
      : index_(std::move(index)), device_(device), messages_(std::move(messages)) {
    for (size_t i = 0; i < index_.image_ids.size(); ++i) position_of_.emplace(index_.image_ids[i], i);
  }

  std::vector<std::vector<image_t>> MostSimilarImages(const std::vector<image_t>& query_image_ids,
                                                      int num_images) override {
    std::vector<std::vector<image_t>> result(query_image_ids.size());
    if (num_images <= 0) return result;
    // An image without an entry in the index has no words to ask with.
    std::vector<size_t> asked;
    std::vector<uint32_t> positions;
    for (size_t q = 0; q < query_image_ids.size(); ++q) {
      const auto position = position_of_.find(query_image_ids[q]);
      if (position == position_of_.end()) continue;
      asked.push_back(q);
      positions.push_back(static_cast<uint32_t>(position->second));
    }
    const auto start = std::chrono::steady_clock::now();
    const NeighborSearch search =
        SearchNeighbors(*index_.index, &positions, static_cast<size_t>(num_images), device_);
    const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    if (!search.gpu_fallback.empty() && messages_.warning) {
      messages_.warning("loop detection: " + search.gpu_fallback + "; querying on the CPU");
    }
    if (messages_.info) {
      std::ostringstream line;
      line.setf(std::ios::fixed);
      line.precision(3);
      line << "Loop detection retrieval: " << Plural(positions.size(), "query") << " " << SearchPlace(search.gpu_index)
           << " in " << seconds << " s";
      messages_.info(line.str());
    }
    for (size_t a = 0; a < asked.size(); ++a) {
      for (const RetrievalNeighbor& neighbor : search.neighbors[a]) {
        result[asked[a]].push_back(index_.image_ids[neighbor.image]);
      }
    }
    return result;
  }

 private:
  DatabaseRetrievalIndex index_;
  RetrievalDevice device_;
  RetrievalMessages messages_;
  std::unordered_map<image_t, size_t> position_of_;
};

}  // namespace

std::unique_ptr<ImageRetrieval> CreateImageRetrievalForRun(const MatcherCommandOptions& options,
                                                           const std::string& database_path,
                                                           const std::vector<image_t>& image_ids,
                                                           RetrievalMessages messages) {
  const SequentialPairingOptions& sequential = options.sequential;
  RetrievalOptions retrieval;
  retrieval.num_images = sequential.loop_detection_num_images;
  retrieval.max_num_features = sequential.loop_detection_max_num_features;
  // COLMAP's loop_detection_num_nearest_neighbors is the number of visual
  // words of the tree one query feature is assigned to (default 1); here
  // it is the number of hash cells a query feature looks up per table, its
  // own and the nearest across its least certain bits, which is the same
  // idea. Values beyond the cells the retrieval can spread to are capped
  // rather than refused, so that COLMAP command lines run unchanged.
  retrieval.num_nearest_neighbors =
      std::min(std::max(sequential.loop_detection_num_nearest_neighbors, 1), RetrievalOptions::kMaxNearestNeighbors);
  retrieval.num_threads = sequential.num_threads;
  retrieval.random_seed = options.random_seed;
  DatabaseRetrievalIndex index = BuildDatabaseRetrievalIndex(database_path, retrieval, image_ids);
  return std::make_unique<DatabaseImageRetrieval>(std::move(index), RetrievalDeviceForRun(options),
                                                  std::move(messages));
}

std::string LoopDetectionUnavailableMessage() {
  return "--SequentialMatching.loop_detection 1 needs an image retrieval, and none was given";
}

SelectedPairs SelectSequentialPairs(const Database& database, const std::vector<Image>& images,
                                    const SequentialPairingOptions& options, ImageRetrieval* retrieval) {
  if (options.loop_detection && retrieval == nullptr) throw std::invalid_argument(LoopDetectionUnavailableMessage());
  const std::unordered_map<image_t, uint32_t> frames =
      options.expand_rig_images ? ReadImageFrames(database) : std::unordered_map<image_t, uint32_t>();
  std::vector<SequenceImage> sequence;
  sequence.reserve(images.size());
  for (const Image& image : images) {
    const auto frame = frames.find(image.image_id);
    sequence.push_back({image.image_id, image.name, image.camera_id, frame == frames.end() ? 0u : frame->second});
  }
  SelectedPairs selected;
  selected.pairs = SequentialPairs(sequence, options);
  selected.notes.push_back("Sequential pairs: " + std::to_string(selected.pairs.size()) + " among " +
                           Plural(images.size(), "image") + " in name order (overlap " +
                           std::to_string(options.overlap) + (options.quadratic_overlap ? ", quadratic" : "") + ")");
  if (!options.vocab_tree_path.empty()) {
    selected.warnings.push_back("--SequentialMatching.vocab_tree_path is not used: loop detection retrieves from the "
                                "cascade's codes, without a vocabulary tree");
  }
  if (options.loop_detection) {
    const std::vector<image_t> ordered = OrderByName(sequence);
    const std::vector<image_t> queries = LoopDetectionQueries(ordered, options);
    const std::vector<std::vector<image_t>> retrieved =
        retrieval->MostSimilarImages(queries, LoopDetectionRetrievalCount(options));
    const std::vector<ImagePair> loops = LoopDetectionPairs(ordered, queries, retrieved, options);
    const size_t before = selected.pairs.size();
    selected.pairs = AppendNewPairs(std::move(selected.pairs), loops);
    selected.notes.push_back("Loop detection: " + Plural(queries.size(), "query") + ", " +
                             Plural(loops.size(), "loop pair") + ", " +
                             std::to_string(selected.pairs.size() - before) + " not among the sequential pairs");
  }
  return selected;
}

SelectedPairs SelectSpatialPairs(const Database& database, const std::vector<Image>& images,
                                 const SpatialPairingOptions& options) {
  const DatabasePositionPriors read = ReadPositionPriors(database, options);
  std::unordered_map<image_t, const PositionPrior*> prior_of;
  for (const PositionPrior& prior : read.priors) prior_of.emplace(prior.image_id, &prior);

  std::vector<PositionPrior> usable;
  std::vector<std::string> without_prior, without_position, undefined_system;
  bool has_gps = false, has_cartesian = false;
  for (const Image& image : images) {
    const auto it = prior_of.find(image.image_id);
    if (it == prior_of.end()) {
      without_prior.push_back(image.name);
      continue;
    }
    if (!HasUsablePosition(*it->second, options)) {
      without_position.push_back(image.name);
      continue;
    }
    usable.push_back(*it->second);
    switch (it->second->coordinate_system) {
      case PriorCoordinateSystem::kWgs84: has_gps = true; break;
      case PriorCoordinateSystem::kCartesian: has_cartesian = true; break;
      case PriorCoordinateSystem::kUndefined:
        has_cartesian = true;
        undefined_system.push_back(image.name);
        break;
    }
  }
  SelectedPairs selected;
  const std::string left_out = " and are left out of spatial matching, as COLMAP leaves them out: ";
  if (!without_prior.empty()) {
    selected.warnings.push_back(std::to_string(without_prior.size()) + " of the " + std::to_string(images.size()) +
                                " images " + (without_prior.size() == 1 ? "has" : "have") + " no position prior in " + read.source + left_out + NameList(without_prior));
  }
  if (!without_position.empty()) {
    selected.warnings.push_back(ImagesHave(without_position.size()) + " a prior without a finite " +
                                (options.ignore_z ? "x and y" : "x, y and z") + " (" + read.source + ")" + left_out +
                                NameList(without_position));
  }
  if (!undefined_system.empty()) {
    selected.warnings.push_back(ImagesHave(undefined_system.size()) +
                                " a prior of undefined coordinate system in " + read.source +
                                ", read as Cartesian as COLMAP reads it: " + NameList(undefined_system));
  }
  if (has_gps && has_cartesian) {
    selected.warnings.push_back("the position priors mix GPS and Cartesian coordinates (" + read.source +
                                "); distances between the two kinds mean nothing");
  }
  if (usable.empty()) {
    throw std::runtime_error("no image of " + database.path() + " has a usable position prior (looked in " +
                             read.source + "); spatial_matcher needs them");
  }
  selected.pairs = SpatialPairs(usable, options);
  if (selected.pairs.empty()) {
    std::ostringstream text;
    text << "no image has a neighbour within --SpatialMatching.max_distance " << options.max_distance
         << (has_gps ? " m (GPS priors" : " (Cartesian priors") << ", " << read.source << ")";
    if (read.source.find("prior_tx") != std::string::npos) {
      text << "; COLMAP 3.8's prior columns are read as " << (options.is_gps ? "GPS" : "Cartesian")
           << " as --SpatialMatching.is_gps says";
    }
    selected.warnings.push_back(text.str());
  }
  std::string unit = has_gps ? " m (GPS priors, compared in ECEF)" : " (Cartesian priors)";
  std::ostringstream distance;
  distance << options.max_distance;
  selected.notes.push_back("Spatial pairs: " + std::to_string(selected.pairs.size()) + " among " +
                           Plural(usable.size(), "image") + " with a position prior (" + read.source +
                           "), up to " + std::to_string(options.max_num_neighbors) + " neighbours within " +
                           distance.str() + unit + (options.ignore_z ? ", heights ignored" : ""));
  return selected;
}

}  // namespace colmap
}  // namespace cashash
