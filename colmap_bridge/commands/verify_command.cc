#include "colmap_bridge/commands/verify_command.h"

#include <sqlite3.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <iomanip>
#include <iostream>
#include <stdexcept>
#include <unordered_map>
#include <unordered_set>

#include "cashash/pipeline/pair_generation.h"
#include "cashash/pipeline/schedule_sizing.h"
#include "cashash/pipeline/schedule_sizing.h"
#include "cashash/base/pair_id.h"
#include "colmap_bridge/completed_pairs.h"
#include "colmap_bridge/database_pipeline_io.h"
#include "colmap_bridge/sqlite_statement.h"
#include "colmap_bridge/api/run_devices.h"
#include "colmap_bridge/api/verifier_selection.h"
#include "colmap_bridge/commands/console.h"

namespace cashash {
namespace colmap {
namespace {

// The pair ids of table matches, through a read-only connection of our own
// (the pipeline's connections read features and write results).
std::vector<pair_t> ReadMatchedPairIds(const std::string& database_path) {
  sqlite3* db = nullptr;
  if (sqlite3_open_v2(database_path.c_str(), &db, SQLITE_OPEN_READONLY, nullptr) != SQLITE_OK) {
    const std::string message = db ? sqlite3_errmsg(db) : "out of memory";
    sqlite3_close(db);
    throw DatabaseError("cannot open " + database_path + ": " + message);
  }
  std::vector<pair_t> pair_ids;
  try {
    SqliteStatement s(db, "SELECT pair_id FROM matches ORDER BY pair_id");
    while (s.Step()) pair_ids.push_back(static_cast<pair_t>(s.ColumnInt64(0)));
  } catch (...) {
    sqlite3_close(db);
    throw;
  }
  sqlite3_close(db);
  return pair_ids;
}

// Keypoints only (verification needs no descriptors); remembers each image's
// keypoint count so that stored match indices can be checked against it.
class KeypointSource : public FeatureSource {
 public:
  explicit KeypointSource(DatabaseFeatureSource* source) : source_(source) {}

  ImageFeatures LoadFeatures(image_t image_id) override {
    ImageFeatures features;
    features.image_id = image_id;
    features.keypoints = source_->database().ReadKeypoints(image_id);
    for (const Keypoint& k : features.keypoints) {
      if (!std::isfinite(k.x) || !std::isfinite(k.y)) {
        throw DatabaseError("image " + std::to_string(image_id) + " (" + source_->image(image_id).name +
                            "): table keypoints holds a NaN or infinite position");
      }
    }
    num_keypoints_[image_id] = features.keypoints.size();
    return features;
  }
  const Camera& CameraOfImage(image_t image_id) const override { return source_->CameraOfImage(image_id); }
  size_t NumKeypoints(image_t image_id) const { return num_keypoints_.at(image_id); }
  Database& database() { return source_->database(); }

 private:
  DatabaseFeatureSource* source_;
  std::unordered_map<image_t, size_t> num_keypoints_;
};

// A "matcher" that returns the matches stored in the database, so that the
// pipeline's loading, verification and writing stages serve verification
// alone. Runs on the pipeline's loading thread, as KeypointSource does.
class StoredMatches : public FeatureMatcher {
 public:
  explicit StoredMatches(KeypointSource* source) : FeatureMatcher(MatcherTraits{"stored-matches"}), source_(source) {}
  void AddImage(const Image&) override {}
  void RemoveImage(image_t) override {}
  std::vector<FeatureMatches> Match(const std::vector<ImagePair>& pairs,
                                    const std::vector<EpipolarGuide>& guides = {}) override {
    CheckGuides(pairs, guides);
    std::vector<FeatureMatches> out;
    out.reserve(pairs.size());
    for (const ImagePair& pair : pairs) {
      FeatureMatches matches = source_->database().ReadMatches(pair.first, pair.second);
      const size_t n1 = source_->NumKeypoints(pair.first), n2 = source_->NumKeypoints(pair.second);
      for (const FeatureMatch& m : matches) {
        if (m.point2D_idx1 >= n1 || m.point2D_idx2 >= n2) {
          throw DatabaseError("matches of images " + std::to_string(pair.first) + " and " +
                              std::to_string(pair.second) + " refer to keypoint " +
                              std::to_string(m.point2D_idx1 >= n1 ? m.point2D_idx1 : m.point2D_idx2) +
                              ", beyond the image's " + std::to_string(m.point2D_idx1 >= n1 ? n1 : n2) +
                              " keypoints");
        }
      }
      out.push_back(std::move(matches));
    }
    return out;
  }

 private:
  KeypointSource* source_;
};


}  // namespace

MatchingSummary VerifyExistingMatches(const std::string& database_path, const MatcherCommandOptions& options,
                                      const MatchingCallbacks& callbacks) {
  MatcherCommandOptions checked = options;
  checked.database_path = database_path;
  const std::string problem = CheckMatcherCommandOptions(checked);
  if (!problem.empty()) throw std::invalid_argument(problem);

  DatabaseFeatureSource database_source(database_path,
                                        [&callbacks](const std::string& text) { Warn(callbacks, text); });
  if (callbacks.database_opened) callbacks.database_opened();
  std::unordered_set<image_t> known_images;
  for (const Image& image : database_source.images()) known_images.insert(image.image_id);
  std::vector<ImagePair> pairs;
  for (const pair_t pair_id : ReadMatchedPairIds(database_path)) {
    const ImagePair pair = PairIdToImagePair(pair_id);
    if (!known_images.count(pair.first) || !known_images.count(pair.second)) {
      throw DatabaseError("table matches holds pair " + std::to_string(pair_id) + " of images " +
                          std::to_string(pair.first) + " and " + std::to_string(pair.second) +
                          ", not both in table images");
    }
    pairs.push_back(pair);
  }

  MatchingSummary summary;
  summary.pairs_requested = pairs.size();
  const size_t block = static_cast<size_t>(checked.block_size > 0 ? checked.block_size : kDefaultBlockSize);
  std::vector<PairChunk> chunks = ListPairChunks(pairs, block * block, 2 * block);
  if (!checked.overwrite) {
    std::vector<image_t> image_ids(known_images.begin(), known_images.end());
    std::sort(image_ids.begin(), image_ids.end());
    const CompletedPairs done = ReadCompletedPairs(database_source.database(), image_ids, chunks);
    chunks = RemovePairs(std::move(chunks),
                         [&](const ImagePair& pair) { return done.Contains(pair.first, pair.second); });
  }
  size_t num_pairs = 0;
  for (const PairChunk& chunk : chunks) num_pairs += chunk.pairs.size();
  summary.pairs_skipped = pairs.size() - num_pairs;
  if (summary.pairs_skipped > 0) {
    Info(callbacks, "Skipping " + std::to_string(summary.pairs_skipped) + " of " + std::to_string(pairs.size()) +
                        " pairs already verified (use --overwrite 1 to verify them again)");
  }
  if (num_pairs == 0) {
    Info(callbacks, "Nothing to verify.");
    return summary;
  }

  KeypointSource source(&database_source);
  StoredMatches stored(&source);
  const RunDevices devices = ChooseRunDevices(checked, MachineDeviceFacts());
  for (const std::string& text : devices.warnings) Warn(callbacks, text);
  // The verifier's device memory under --max_gpu_memory, as in a matching run.
  size_t gpu_budget = 0;
  if (!checked.max_gpu_memory.empty()) ParseMemorySize(checked.max_gpu_memory, &gpu_budget);
  RunGpuResources gpu(gpu_budget);
  std::unique_ptr<BatchVerifier> verifier =
      CreateBatchVerifierOnDevice(checked, devices.gpu_indices.empty() ? -1 : devices.gpu_indices.front(), &gpu);
  DatabaseResultSink sink(database_path, true);
  PipelineOptions pipeline_options;
  pipeline_options.num_threads = checked.sift.num_threads;
  pipeline_options.two_view = checked.two_view;
  MatchingPipeline pipeline(pipeline_options, &source, &stored, &sink);
  pipeline.SetBatchVerifier(verifier.get());
  if (callbacks.progress) pipeline.SetProgressCallback(callbacks.progress);
  if (callbacks.stop != nullptr) pipeline.SetStopFlag(callbacks.stop);
  summary.matcher_name = "stored matches, " + verifier->Name() + " verification";
  Info(callbacks, "Verifier: " + verifier->Name());
  summary.pipeline = pipeline.Run(chunks);
  return summary;
}

int RunGeometricVerifier(int argc, const char* const* argv) {
  MatcherCommandOptions options;
  switch (ParseMatcherCommandOptions("geometric_verifier", argc, argv, &options)) {
    case ParseOutcome::kHelpShown:
      return EXIT_SUCCESS;
    case ParseOutcome::kError:
      return EXIT_FAILURE;
    case ParseOutcome::kRun:
      break;
  }
  MatchingCallbacks callbacks;
  callbacks.database_opened = []() { PrintHeading("Geometric verification"); };
  callbacks.info = [](const std::string& text) { std::cout << text << std::endl; };
  callbacks.warning = PrintWarning;
  callbacks.progress = [](const PipelineProgress& p) {
    std::cout << "Verified " << p.pairs_done << "/" << p.pairs_total << " pairs (" << std::fixed
              << std::setprecision(1) << 100.0 * p.pairs_done / p.pairs_total << "%) in " << std::setprecision(3)
              << p.elapsed_seconds << "s" << std::endl;
  };
  const StopOnInterrupt interrupt;
  callbacks.stop = interrupt.stop_flag();
  int code = EXIT_FAILURE;
  try {
    const MatchingSummary summary = VerifyExistingMatches(options.database_path, options, callbacks);
    code = EXIT_SUCCESS;
    if (!summary.matcher_name.empty()) {
      const PipelineStats& stats = summary.pipeline;
      std::cout << std::fixed << std::setprecision(3) << "Summary: " << stats.pairs_done << " pairs in "
                << stats.seconds_total << " s with " << summary.matcher_name << "; " << stats.raw_matches
                << " matches, " << stats.verified_pairs << " verified pairs, " << stats.inlier_matches
                << " inlier matches; verification " << stats.seconds_verification << " s" << std::endl;
      if (stats.stopped) {
        std::cout << "Stopped after " << stats.pairs_done << " of " << stats.pairs_total
                  << " pairs; every finished block is committed, run again to resume." << std::endl;
        code = 130;
      }
    }
  } catch (const std::exception& e) {
    std::cerr << "ERROR: " << e.what() << std::endl;
  }
  return code;
}

}  // namespace colmap
}  // namespace cashash
