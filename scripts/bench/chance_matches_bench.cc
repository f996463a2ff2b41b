// Chance matches of the CPU Cascade Hashing matcher against exact brute
// force, on every pair of a COLMAP feature database (best a generated
// street, where most pairs do not overlap).
//
//   chance_matches_bench --database DB [--threads T] [--seed S]
//       [--settings "tables,bits,tau,top_k[,rematch];..."] [--max_chance_ratio R]
//       [--min_kept K]
//
// A pair overlaps when brute force's matches pass geometric verification
// (config >= CALIBRATED, COLMAP's defaults). For each setting it prints, on
// pairs that do not overlap, the raw matches and the pairs with at least
// min_num_inliers raw matches (each such pair costs a RANSAC run), both
// against brute force; on pairs that overlap, the share of brute force's
// verified inlier matches that the cascade returns as raw matches; and, after
// verifying the cascade's matches, verified pairs and inlier matches.
// A fifth number in a setting is --CasHash.exact_rematch_min_matches: pairs
// with at least that many cascade matches get brute force's matches, as a
// run's exact rematch stage does (0 or absent: the cascade's kept).
// With --max_chance_ratio it exits 1 when a setting leaves more than R times
// brute force's raw matches on the pairs that do not overlap, and with
// --min_kept K when it verifies fewer than K times brute force's verified
// pairs or inlier matches (checks for the integration tests).
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <sstream>
#include <string>
#include <unordered_map>
#include <vector>

#include "cashash/pipeline/batch_verifier.h"
#include "cashash/matching/brute_force_matcher.h"
#include "cashash/matching/cascade_hashing.h"
#include "cashash/matching/cascade_matcher.h"
#include "cashash/base/parallel_for.h"
#include "cashash/geometry/two_view_geometry.h"
#include "colmap_bridge/database.h"
#include "../../tests/support/cascade_options.h"

namespace {

using namespace cashash;
using cashash::testing_support::CascadeOptions;

struct Setting {
  int tables = 8, bits = 7, tau = 43, top_k = 16, rematch = 0;
};

std::vector<Setting> ParseSettings(const std::string& text) {
  std::vector<Setting> settings;
  std::stringstream all(text);
  std::string item;
  while (std::getline(all, item, ';')) {
    Setting s;
    if (std::sscanf(item.c_str(), "%d,%d,%d,%d,%d", &s.tables, &s.bits, &s.tau, &s.top_k, &s.rematch) < 4) {
      throw std::invalid_argument("bad setting '" + item + "' (want tables,bits,tau,top_k[,rematch])");
    }
    settings.push_back(s);
  }
  return settings;
}

size_t CountCommon(FeatureMatches a, FeatureMatches b) {
  std::sort(a.begin(), a.end());
  std::sort(b.begin(), b.end());
  size_t common = 0;
  for (size_t i = 0, j = 0; i < a.size() && j < b.size();) {
    if (a[i] == b[j]) ++common, ++i, ++j;
    else if (a[i] < b[j]) ++i;
    else ++j;
  }
  return common;
}

}  // namespace

int main(int argc, char** argv) {
  std::string database, settings_text = "8,7,43,16";
  int threads = -1;
  uint64_t seed = 0;
  double max_chance_ratio = 0;
  double min_kept = 0;
  bool failed = false;
  for (int i = 1; i + 1 < argc; i += 2) {
    const std::string flag = argv[i], value = argv[i + 1];
    if (flag == "--database") database = value;
    else if (flag == "--threads") threads = std::atoi(value.c_str());
    else if (flag == "--seed") seed = std::strtoull(value.c_str(), nullptr, 10);
    else if (flag == "--settings") settings_text = value;
    else if (flag == "--max_chance_ratio") max_chance_ratio = std::atof(value.c_str());
    else if (flag == "--min_kept") min_kept = std::atof(value.c_str());
    else {
      std::fprintf(stderr, "unknown option %s\n", flag.c_str());
      return 2;
    }
  }
  if (database.empty()) {
    std::fprintf(stderr, "usage: %s --database DB [--threads T] [--seed S] [--settings ...]\n", argv[0]);
    return 2;
  }
  try {
    const colmap::Database db(database, /*read_only=*/true);
    std::unordered_map<camera_t, Camera> cameras;
    for (const Camera& c : db.ReadAllCameras()) cameras[c.camera_id] = c;
    const std::vector<Image> images = db.ReadAllImages();
    const size_t n = images.size();
    std::vector<FeatureDescriptors> descriptors(n);
    std::vector<std::vector<Eigen::Vector2d>> points(n);
    for (size_t i = 0; i < n; ++i) {
      descriptors[i] = db.ReadDescriptors(images[i].image_id);
      points[i] = KeypointPositions(db.ReadKeypoints(images[i].image_id));
    }
    std::vector<std::pair<size_t, size_t>> pairs;
    for (size_t a = 0; a < n; ++a)
      for (size_t b = a + 1; b < n; ++b) pairs.push_back({a, b});
    const SiftMatchingOptions sift;
    const TwoViewGeometryOptions two_view;
    auto verify = [&](size_t p, const FeatureMatches& matches) {
      TwoViewGeometryOptions o = two_view;
      o.random_seed = PairRandomSeed(0, {images[pairs[p].first].image_id, images[pairs[p].second].image_id});
      return EstimateTwoViewGeometry(cameras.at(images[pairs[p].first].camera_id), points[pairs[p].first],
                                     cameras.at(images[pairs[p].second].camera_id), points[pairs[p].second],
                                     matches, o);
    };

    std::vector<WideDescriptors> wide;
    for (const auto& d : descriptors) wide.push_back(WidenDescriptors(d, d.rows()));
    std::vector<FeatureMatches> exact(pairs.size());
    std::vector<TwoViewGeometry> exact_geometry(pairs.size());
    ParallelFor(pairs.size(), threads, [&](size_t p) {
      exact[p] = BruteForceMatchPair(wide[pairs[p].first], wide[pairs[p].second], sift);
      exact_geometry[p] = verify(p, exact[p]);
    });
    size_t overlap = 0, exact_chance_raw = 0, exact_chance_pairs = 0, exact_inliers = 0;
    for (size_t p = 0; p < pairs.size(); ++p) {
      if (exact_geometry[p].config >= kCalibrated) {
        ++overlap;
        exact_inliers += exact_geometry[p].inlier_matches.size();
      } else {
        exact_chance_raw += exact[p].size();
        exact_chance_pairs += exact[p].size() >= static_cast<size_t>(two_view.min_num_inliers);
      }
    }
    std::printf("# %zu images, %zu pairs, %zu overlap (brute force verified, %zu inlier matches)\n", n,
                pairs.size(), overlap, exact_inliers);
    std::printf("# brute force on pairs that do not overlap: %zu raw matches, %zu pairs with >= %d\n\n",
                exact_chance_raw, exact_chance_pairs, two_view.min_num_inliers);
    std::printf("| tables x bits | tau | top_k | rematch | chance raw matches (x brute force) | chance pairs >= %d (x) | "
                "inlier recall | verified pairs (x) | inlier matches (x) | matching s |\n",
                two_view.min_num_inliers);
    std::printf("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n");

    std::vector<const FeatureDescriptors*> pointers;
    for (const auto& d : descriptors) pointers.push_back(&d);
    const MeanDescriptor mean = ComputeMeanDescriptor(pointers);
    for (const Setting& s : ParseSettings(settings_text)) {
      CasHashOptions options = CascadeOptions();
      options.num_tables = s.tables;
      options.bits_per_table = s.bits;
      options.tau = s.tau;
      options.top_k = s.top_k;
      options.random_seed = seed;
      const CascadeProjections projections = GenerateCascadeProjections(options);
      std::vector<CascadeImage> hashed(n);
      ParallelFor(n, threads, [&](size_t i) {
        hashed[i] = BuildCascadeImage(descriptors[i], descriptors[i].rows(), projections, mean);
      });
      const size_t workers = NumParallelWorkers(pairs.size(), threads);
      std::vector<CascadeScratch> scratch(workers);
      std::vector<FeatureMatches> cascade(pairs.size());
      const auto start = std::chrono::steady_clock::now();
      ParallelForWorkers(pairs.size(), threads, [&](size_t p, size_t worker) {
        cascade[p] = CascadeMatchPair(hashed[pairs[p].first], hashed[pairs[p].second], sift, options,
                                      &scratch[worker], nullptr);
      });
      const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
      // The exact rematch: brute force's matches (computed above) replace the
      // cascade's on pairs that may verify. Its time is not in `seconds`.
      if (s.rematch > 0) {
        for (size_t p = 0; p < pairs.size(); ++p) {
          if (cascade[p].size() >= static_cast<size_t>(s.rematch)) cascade[p] = exact[p];
        }
      }
      std::vector<TwoViewGeometry> geometry(pairs.size());
      ParallelFor(pairs.size(), threads, [&](size_t p) { geometry[p] = verify(p, cascade[p]); });
      size_t chance_raw = 0, chance_pairs = 0, kept = 0, verified = 0, inliers = 0;
      for (size_t p = 0; p < pairs.size(); ++p) {
        if (exact_geometry[p].config >= kCalibrated) {
          kept += CountCommon(exact_geometry[p].inlier_matches, cascade[p]);
        } else {
          chance_raw += cascade[p].size();
          chance_pairs += cascade[p].size() >= static_cast<size_t>(two_view.min_num_inliers);
        }
        if (geometry[p].config >= kCalibrated) {
          ++verified;
          inliers += geometry[p].inlier_matches.size();
        }
      }
      auto ratio = [](size_t a, size_t b) { return b ? static_cast<double>(a) / b : 0.0; };
      std::printf("| %d x %d | %d | %d | %d | %zu (%.2f) | %zu (%.2f) | %.4f | %zu (%.3f) | %zu (%.3f) | %.2f |\n", s.tables,
                  s.bits, s.tau, s.top_k, s.rematch, chance_raw, ratio(chance_raw, exact_chance_raw), chance_pairs,
                  ratio(chance_pairs, exact_chance_pairs), ratio(kept, exact_inliers), verified,
                  ratio(verified, overlap), inliers, ratio(inliers, exact_inliers), seconds);
      std::fflush(stdout);
      if (max_chance_ratio > 0 && chance_raw > max_chance_ratio * exact_chance_raw) {
        std::printf("FAILED: %zu chance raw matches, more than %.2f x brute force's %zu\n", chance_raw,
                    max_chance_ratio, exact_chance_raw);
        failed = true;
      }
      if (min_kept > 0 && (verified < min_kept * overlap || inliers < min_kept * exact_inliers)) {
        std::printf("FAILED: %zu verified pairs and %zu inlier matches, below %.3f x brute force's %zu and %zu\n",
                    verified, inliers, min_kept, overlap, exact_inliers);
        failed = true;
      }
    }
  } catch (const std::exception& e) {
    std::fprintf(stderr, "ERROR: %s\n", e.what());
    return 1;
  }
  return failed ? 1 : 0;
}
