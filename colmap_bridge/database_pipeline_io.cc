#include "colmap_bridge/database_pipeline_io.h"

#include <algorithm>
#include <cmath>
#include <iostream>

#include "cashash/geometry/camera_models.h"
#include "cashash/base/pair_id.h"

namespace cashash {
namespace colmap {

DatabaseFeatureSource::DatabaseFeatureSource(const std::string& database_path,
                                             std::function<void(const std::string&)> warning)
    : database_(database_path, /*read_only=*/true),
      readers_([database_path]() { return std::make_unique<Database>(database_path, /*read_only=*/true); }),
      warning_(std::move(warning)) {
  images_ = database_.ReadAllImages();
  for (Camera& camera : database_.ReadAllCameras()) {
    CheckCamera(camera);
    cameras_.emplace(camera.camera_id, std::move(camera));
  }
  std::unordered_map<std::string, image_t> ids_by_name;
  for (size_t i = 0; i < images_.size(); ++i) {
    image_index_.emplace(images_[i].image_id, i);
    // COLMAP's schema makes names UNIQUE; a hand-made table may not, and pair
    // lists and the mapper find images by name.
    const auto named = ids_by_name.emplace(images_[i].name, images_[i].image_id);
    if (!named.second) {
      throw DatabaseError("table images: images " + std::to_string(named.first->second) + " and " +
                          std::to_string(images_[i].image_id) + " have the same name '" + images_[i].name + "'");
    }
    if (!cameras_.count(images_[i].camera_id)) {
      throw DatabaseError("table images: image " + std::to_string(images_[i].image_id) + " (" + images_[i].name +
                          ") refers to camera " + std::to_string(images_[i].camera_id) +
                          ", which is not in table cameras");
    }
  }
}

void DatabaseFeatureSource::CheckCamera(const Camera& camera) {
  const std::string label = "table cameras: camera " + std::to_string(camera.camera_id);
  const int expected = CameraModelNumParams(camera.model_id);
  if (expected < 0) {
    // A model of a newer COLMAP, or garbage: verification needs no intrinsics
    // unless both cameras of a pair have a focal prior.
    Warn(label + " has model id " + std::to_string(camera.model_id) +
         ", unknown to cashash; its images are verified with F and H only");
    return;
  }
  if (static_cast<int>(camera.params.size()) != expected) {
    throw DatabaseError(label + " (" + CameraModelIdToName(camera.model_id) + ") has " +
                        std::to_string(camera.params.size()) + " params, the model has " +
                        std::to_string(expected));
  }
  for (size_t i = 0; i < camera.params.size(); ++i) {
    if (!std::isfinite(camera.params[i])) {
      throw DatabaseError(label + ": param " + std::to_string(i) + " is not finite");
    }
  }
}

void DatabaseFeatureSource::Warn(const std::string& text) {
  if (warning_) {
    warning_(text);
  } else {
    std::cerr << "WARNING: " << text << std::endl;
  }
}

const Image& DatabaseFeatureSource::image(image_t image_id) const { return images_.at(image_index_.at(image_id)); }

void DatabaseFeatureSource::WarnAboutKeypointsOutside(image_t image_id, const Keypoints& keypoints) {
  const Camera& camera = CameraOfImage(image_id);
  if (camera.width == 0 || camera.height == 0) return;
  // Pixel centres run from 0.5 to width - 0.5; a pixel of slack on each side.
  const double max_x = static_cast<double>(camera.width) + 1.0;
  const double max_y = static_cast<double>(camera.height) + 1.0;
  size_t outside = 0;
  size_t first = 0;
  for (size_t i = 0; i < keypoints.size(); ++i) {
    const Keypoint& kp = keypoints[i];
    if (kp.x < -1.0 || kp.y < -1.0 || kp.x > max_x || kp.y > max_y) {
      if (outside++ == 0) first = i;
    }
  }
  if (outside == 0) return;
  // Loading threads warn one at a time (the callback need not be thread-safe).
  std::lock_guard<std::mutex> lock(warned_mutex_);
  if (!warned_images_.insert(image_id).second) return;
  const Keypoint& kp = keypoints[first];
  const std::string text = "image " + std::to_string(image_id) + " (" + image(image_id).name + "): " +
                           std::to_string(outside) + " of " + std::to_string(keypoints.size()) +
                           " keypoints lie outside the " + std::to_string(camera.width) + " x " +
                           std::to_string(camera.height) + " image (first: row " + std::to_string(first) + " at " +
                           std::to_string(kp.x) + ", " + std::to_string(kp.y) + "); matching them anyway";
  Warn(text);
}

ImageFeatures DatabaseFeatureSource::LoadFeatures(image_t image_id) {
  ImageFeatures features;
  features.image_id = image_id;
  {
    std::unique_ptr<Database> reader = readers_.Acquire();
    // A reader that threw is dropped: its statements may be mid-step.
    features.keypoints = reader->ReadKeypoints(image_id);
    features.descriptors = reader->ReadDescriptors(image_id);
    readers_.Release(std::move(reader));
  }
  if (features.keypoints.size() != features.descriptors.rows()) {
    const Image& im = image(image_id);
    throw DatabaseError("image " + std::to_string(image_id) + " (" + im.name + "): table keypoints has " +
                        std::to_string(features.keypoints.size()) + " rows but table descriptors has " +
                        std::to_string(features.descriptors.rows()));
  }
  WarnAboutKeypointsOutside(image_id, features.keypoints);
  return features;
}

const Camera& DatabaseFeatureSource::CameraOfImage(image_t image_id) const {
  return cameras_.at(image(image_id).camera_id);
}

DatabaseResultSink::DatabaseResultSink(const std::string& database_path, bool write_two_view_geometries)
    : DatabaseResultSink(database_path, Options{write_two_view_geometries, true, false}) {}

DatabaseResultSink::DatabaseResultSink(const std::string& database_path, const Options& options)
    : lock_(database_path),
      database_(database_path, /*read_only=*/false,
                // One thread at a time: the pipeline's writer (LockedSink under MPI).
                DatabaseOptions{options.busy_timeout_ms, options.cache_mib, options.disk_sync, true}),
      options_(options) {
  if (database_.UsesWriteAheadLog()) {
    checkpointer_ = std::make_unique<WalCheckpointer>(database_path);
    database_.HandOverLogFolding([this](int pages) { logged_pages_ = pages; });
  }
}

DatabaseResultSink::~DatabaseResultSink() {
  try {
    Flush();
  } catch (const std::exception& e) {
    // Nothing half-written stays: the failed commit was rolled back.
    std::cerr << "WARNING: " << e.what() << "; the chunks not yet committed are matched again by the next run"
              << std::endl;
  }
}

void DatabaseResultSink::WriteRows(const std::vector<PairResult>& results) {
  // By pair id and table by table: each statement then lands next to the
  // last one in its table's key order.
  order_.clear();
  empty_pairs_.clear();
  for (size_t k = 0; k < results.size(); ++k) {
    const PairResult& result = results[k];
    if (!options_.write_empty_pairs && result.matches.empty()) {
      empty_pairs_.push_back(ImagePairToPairId(result.pair.first, result.pair.second));
      if (options_.replace_existing) database_.DeleteMatchesAndGeometry(result.pair.first, result.pair.second);
      continue;
    }
    order_.push_back(k);
  }
  const auto pair_id_of = [&](size_t k) { return ImagePairToPairId(results[k].pair.first, results[k].pair.second); };
  std::sort(order_.begin(), order_.end(), [&](size_t a, size_t b) { return pair_id_of(a) < pair_id_of(b); });
  rows_.clear();
  for (size_t k : order_) {
    const PairResult& r = results[k];
    rows_.push_back(PairRowsRef{r.pair.first, r.pair.second, &r.matches, &r.geometry});
    pending_bytes_ += sizeof(FeatureMatch) * (r.matches.size() + r.geometry.inlier_matches.size());
  }
  database_.WriteMatchesRows(rows_);
  if (options_.write_two_view_geometries) {
    database_.WriteTwoViewGeometryRows(rows_);
  } else if (options_.replace_existing) {
    // An old verification of other matches: kept, it would make the pair
    // look done to a resumed run.
    for (const PairRowsRef& row : rows_) database_.DeleteTwoViewGeometry(row.image_id1, row.image_id2);
  }
  // In the chunk's transaction: recorded exactly when the chunk is.
  database_.RecordEmptyPairs(empty_pairs_);
  pending_rows_ += order_.size() * (options_.write_two_view_geometries ? 2 : 1);
  pending_empty_pairs_ += empty_pairs_.size();
}

void DatabaseResultSink::WriteChunk(const std::vector<PairResult>& results) {
  if (!in_transaction_) {
    database_.BeginTransaction();
    in_transaction_ = true;
    transaction_start_ = std::chrono::steady_clock::now();
  }
  try {
    WriteRows(results);
  } catch (...) {
    in_transaction_ = false;
    pending_rows_ = pending_empty_pairs_ = pending_bytes_ = 0;
    database_.Rollback();
    throw;
  }
  const double open_seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - transaction_start_).count();
  const bool log_bound = options_.commit_mib > 0 && pending_bytes_ >= static_cast<size_t>(options_.commit_mib) << 20;
  if (open_seconds >= options_.commit_seconds || log_bound) Commit();
}

void DatabaseResultSink::Flush() {
  if (in_transaction_) Commit();
}

void DatabaseResultSink::Commit() {
  in_transaction_ = false;
  try {
    database_.Commit();
  } catch (...) {
    pending_rows_ = pending_empty_pairs_ = pending_bytes_ = 0;
    database_.Rollback();
    throw;
  }
  // The cache is room for one transaction's changed pages. Kept after the
  // commit, the pages would fill it with what was written (cache_mib of
  // host memory, for a run of any size), while the next transaction writes
  // mostly other pages (the chunks' key ranges move on with the block
  // rows) and reads the few it shares again. Below options_.kept_cache_mib
  // they stay: short transactions (a commit per chunk) then find the
  // interior pages and the leaves they go on with.
  if (database_.CachedPageBytes() > static_cast<size_t>(options_.kept_cache_mib) << 20) {
    database_.ReleaseCachedPages();
  }
  ++commits_;
  rows_written_ += pending_rows_;
  empty_pairs_recorded_ += pending_empty_pairs_;
  pending_rows_ = pending_empty_pairs_ = pending_bytes_ = 0;
  if (checkpointer_) {
    if (logged_pages_ >= options_.log_pages_before_catch_up) {
      checkpointer_->CatchUp();
    } else {
      checkpointer_->Nudge();
    }
  }
}

}  // namespace colmap
}  // namespace cashash
