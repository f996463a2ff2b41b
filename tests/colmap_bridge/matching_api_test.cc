// The library calls: MatchImagePair on features in memory, and
// MatchExhaustive / MatchPairs on a small COLMAP database of a synthetic
// scene (three views of one point cloud, each point with its own descriptor).
#include <gtest/gtest.h>
#include <sqlite3.h>
#include <unistd.h>

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <numeric>
#include <random>
#include <stdexcept>
#include <string>
#include <vector>

#include "cashash/matching/pair_matching.h"
#include "colmap_bridge/api/matching_api.h"

namespace cashash {
namespace {

namespace fs = std::filesystem;

constexpr int kWidth = 1280, kHeight = 960;
constexpr double kFocal = 1000.0;

// One view of the scene: keypoints, descriptors and for each row the index
// of the 3-D point it sees. Rows are shuffled so that row indices differ
// between views.
struct View {
  Keypoints keypoints;
  FeatureDescriptors descriptors;
  std::vector<int> point_of_row;
};

struct Scene {
  std::vector<Eigen::Vector3d> points;
  std::vector<std::vector<uint8_t>> descriptors;  // one per point
};

Scene MakeScene(int num_points, unsigned seed) {
  Scene scene;
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> xy(-2.5, 2.5), depth(5.0, 9.0);
  std::uniform_int_distribution<int> value(0, 60);
  for (int i = 0; i < num_points; ++i) {
    // The depth, then y, then x, one draw a statement (ordered_draws.h).
    const double z = depth(rng);
    const double y = xy(rng);
    scene.points.emplace_back(xy(rng), y, z);
    // SIFT descriptors have an L2 norm of about 512; the matcher's distance
    // threshold is an angle that assumes it.
    std::vector<double> raw(kDescriptorDim);
    double norm = 0;
    for (double& v : raw) {
      v = value(rng);
      norm += v * v;
    }
    std::vector<uint8_t> d(kDescriptorDim);
    const double scale = 512.0 / std::sqrt(norm);
    for (int k = 0; k < kDescriptorDim; ++k) d[k] = static_cast<uint8_t>(std::lround(raw[k] * scale));
    scene.descriptors.push_back(d);
  }
  return scene;
}

// Camera i sits at x = 0.4 i, turned slightly towards the cloud's centre.
View MakeView(const Scene& scene, int camera_index, unsigned seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> pixel_noise(0.0, 0.3);
  std::uniform_int_distribution<int> byte_noise(-2, 2);
  const Eigen::Matrix3d R(Eigen::AngleAxisd(-0.03 * camera_index, Eigen::Vector3d::UnitY()));
  const Eigen::Vector3d center(0.4 * camera_index, 0.05 * camera_index, 0.0);
  std::vector<int> order(scene.points.size());
  std::iota(order.begin(), order.end(), 0);
  std::shuffle(order.begin(), order.end(), rng);
  View view;
  for (int p : order) {
    const Eigen::Vector3d X = R * (scene.points[p] - center);
    const double x = kFocal * X.x() / X.z() + kWidth / 2 + pixel_noise(rng);
    const double y = kFocal * X.y() / X.z() + kHeight / 2 + pixel_noise(rng);
    if (x < 0 || y < 0 || x >= kWidth || y >= kHeight) continue;
    Keypoint k;
    k.x = static_cast<float>(x);
    k.y = static_cast<float>(y);
    view.keypoints.push_back(k);
    for (uint8_t v : scene.descriptors[p]) {
      view.descriptors.data.push_back(static_cast<uint8_t>(std::clamp(v + byte_noise(rng), 0, 255)));
    }
    view.point_of_row.push_back(p);
  }
  return view;
}

Camera PinholeCamera(bool prior) {
  Camera camera;
  camera.model_id = 1;  // PINHOLE
  camera.width = kWidth;
  camera.height = kHeight;
  camera.params = {kFocal, kFocal, kWidth / 2.0, kHeight / 2.0};
  camera.has_prior_focal_length = prior;
  return camera;
}

size_t CorrectMatches(const FeatureMatches& matches, const View& a, const View& b) {
  size_t correct = 0;
  for (const FeatureMatch& m : matches) {
    correct += a.point_of_row[m.point2D_idx1] == b.point_of_row[m.point2D_idx2];
  }
  return correct;
}

TEST(MatchImagePair, MatchesAndVerifiesFeaturesInMemory) {
  const Scene scene = MakeScene(800, 1);
  const View a = MakeView(scene, 0, 2), b = MakeView(scene, 1, 3);
  ASSERT_GT(a.keypoints.size(), 500u);

  const PairMatchingResult guessed =
      MatchImagePair(a.keypoints, a.descriptors, b.keypoints, b.descriptors, PairMatchingOptions());
  ASSERT_TRUE(guessed.verified);
  EXPECT_GT(guessed.matches.size(), 400u);
  EXPECT_GE(CorrectMatches(guessed.matches, a, b), guessed.matches.size() * 98 / 100);
  // Without intrinsics only F and H can be estimated.
  EXPECT_EQ(guessed.two_view_geometry.config, kUncalibrated);
  EXPECT_GE(guessed.two_view_geometry.inlier_matches.size(), guessed.matches.size() * 95 / 100);

  const Camera camera = PinholeCamera(/*prior=*/true);
  const PairMatchingResult calibrated = MatchImagePair(a.keypoints, a.descriptors, b.keypoints, b.descriptors,
                                                       PairMatchingOptions(), &camera, &camera);
  EXPECT_EQ(calibrated.two_view_geometry.config, kCalibrated);
  EXPECT_EQ(calibrated.matches, guessed.matches);
}

TEST(MatchImagePair, DescriptorsOnlyGiveRawMatches) {
  const Scene scene = MakeScene(300, 4);
  const View a = MakeView(scene, 0, 5), b = MakeView(scene, 1, 6);
  const PairMatchingResult result = MatchImagePair({}, a.descriptors, {}, b.descriptors, PairMatchingOptions());
  EXPECT_FALSE(result.verified);
  EXPECT_EQ(result.two_view_geometry.config, kUndefined);
  EXPECT_GE(CorrectMatches(result.matches, a, b), 150u);
}

// Auto is decided as for a run (ChooseAutoMatcher): MatchImagePair's own
// matcher keeps the cascade's matches, so auto is the cascade; the CPU
// factory itself refuses an undecided auto.
TEST(MatchImagePair, AutoIsTheCascadeAndTheFactoryRefusesItUndecided) {
  const Scene scene = MakeScene(300, 4);
  const View a = MakeView(scene, 0, 5), b = MakeView(scene, 1, 6);
  PairMatchingOptions cascade, automatic;
  cascade.cashash.matcher = MatcherType::kCascade;
  automatic.cashash.matcher = MatcherType::kAuto;
  const PairMatchingResult by_cascade = MatchImagePair(a.keypoints, a.descriptors, b.keypoints, b.descriptors, cascade);
  const PairMatchingResult by_auto = MatchImagePair(a.keypoints, a.descriptors, b.keypoints, b.descriptors, automatic);
  EXPECT_GT(by_cascade.matches.size(), 100u);
  EXPECT_EQ(by_auto.matches, by_cascade.matches);
  EXPECT_THROW(CreateCpuFeatureMatcher(SiftMatchingOptions(), automatic.cashash,
                                       ComputeMeanDescriptor({&a.descriptors, &b.descriptors})),
               std::invalid_argument);
}

TEST(MatchImagePair, RejectsMismatchedRowsAndBadOptions) {
  const Scene scene = MakeScene(100, 7);
  View a = MakeView(scene, 0, 8);
  const View b = MakeView(scene, 1, 9);
  a.keypoints.pop_back();
  try {
    MatchImagePair(a.keypoints, a.descriptors, b.keypoints, b.descriptors, PairMatchingOptions());
    FAIL() << "accepted more descriptors than keypoints";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("image 1 has"), std::string::npos) << e.what();
  }
  PairMatchingOptions bad;
  bad.cashash.top_k = 0;
  EXPECT_THROW(MatchImagePair({}, b.descriptors, {}, b.descriptors, bad), std::invalid_argument);
}

TEST(GuessCamera, SpansKeypointsWithoutFocalPrior) {
  Keypoints keypoints(2);
  keypoints[1].x = 639.5f;
  keypoints[1].y = 479.2f;
  const Camera camera = GuessCamera(keypoints);
  EXPECT_EQ(camera.width, 640u);
  EXPECT_EQ(camera.height, 480u);
  EXPECT_FALSE(camera.has_prior_focal_length);
  EXPECT_DOUBLE_EQ(camera.params[0], 1.2 * 640);
}

// A COLMAP 3.8 database made by `colmap database_creator`, filled with three
// views of one scene through raw SQLite.
class SceneDatabase : public testing::Test {
 protected:
  void SetUp() override {
    if (std::system("command -v colmap > /dev/null 2>&1") != 0) GTEST_SKIP() << "colmap is not installed";
    dir_ = fs::temp_directory_path() / ("cashash_matching_api_test_" + std::to_string(getpid()));
    fs::remove_all(dir_);
    fs::create_directories(dir_);
    path_ = (dir_ / "scene.db").string();
    ASSERT_EQ(std::system(("QT_QPA_PLATFORM=offscreen colmap database_creator --database_path " + path_ +
                           " > /dev/null 2>&1")
                              .c_str()),
              0);
    const Scene scene = MakeScene(700, 11);
    ASSERT_EQ(sqlite3_open(path_.c_str(), &db_), SQLITE_OK);
    const Camera camera = PinholeCamera(/*prior=*/false);
    Insert("INSERT INTO cameras(camera_id, model, width, height, params, prior_focal_length) VALUES (1, 1, " +
               std::to_string(kWidth) + ", " + std::to_string(kHeight) + ", ?, 0)",
           camera.params.data(), camera.params.size() * sizeof(double));
    for (int i = 0; i < 3; ++i) {
      const View view = MakeView(scene, i, 20 + i);
      const std::string id = std::to_string(i + 1);
      Insert("INSERT INTO images(image_id, name, camera_id) VALUES (" + id + ", 'view" + id + ".jpg', 1)", nullptr,
             0);
      Insert("INSERT INTO keypoints VALUES (" + id + ", " + std::to_string(view.keypoints.size()) + ", 6, ?)",
             view.keypoints.data(), view.keypoints.size() * sizeof(Keypoint));
      Insert("INSERT INTO descriptors VALUES (" + id + ", " + std::to_string(view.descriptors.rows()) + ", 128, ?)",
             view.descriptors.data.data(), view.descriptors.data.size());
    }
    sqlite3_close(db_);
    db_ = nullptr;
    options_.use_gpu = false;
  }

  void TearDown() override {
    if (db_ != nullptr) sqlite3_close(db_);
    std::error_code ignored;
    if (!dir_.empty()) fs::remove_all(dir_, ignored);
  }

  // Runs `sql`; its one '?' (if any) is bound to the blob.
  void Insert(const std::string& sql, const void* blob, size_t num_bytes) {
    sqlite3_stmt* stmt = nullptr;
    ASSERT_EQ(sqlite3_prepare_v2(db_, sql.c_str(), -1, &stmt, nullptr), SQLITE_OK) << sql;
    if (blob != nullptr) sqlite3_bind_blob(stmt, 1, blob, static_cast<int>(num_bytes), SQLITE_TRANSIENT);
    EXPECT_EQ(sqlite3_step(stmt), SQLITE_DONE) << sql << ": " << sqlite3_errmsg(db_);
    sqlite3_finalize(stmt);
  }

  fs::path dir_;
  std::string path_;
  sqlite3* db_ = nullptr;
  colmap::MatcherCommandOptions options_;
};

TEST_F(SceneDatabase, ExhaustiveMatchesEveryPairOnceAndResumes) {
  size_t progress_calls = 0, last_done = 0;
  std::vector<std::string> notes, warnings;
  colmap::MatchingCallbacks callbacks;
  callbacks.progress = [&](const PipelineProgress& p) {
    ++progress_calls;
    last_done = p.pairs_done;
  };
  callbacks.info = [&](const std::string& text) { notes.push_back(text); };
  callbacks.warning = [&](const std::string& text) { warnings.push_back(text); };

  // A typed threshold: every pair with 12 cascade matches is matched again
  // exactly (the defaults: DefaultsChooseTablesAndMatcherAndSaySo).
  options_.cashash.exact_rematch_min_matches = 12;
  const colmap::MatchingSummary first = colmap::MatchExhaustive(path_, options_, callbacks);
  EXPECT_EQ(first.pairs_requested, 3u);
  EXPECT_EQ(first.pairs_skipped, 0u);
  // Runs match the pairs that may verify again exactly (all three here).
  EXPECT_EQ(first.matcher_name, "cpu-cascade+exact-rematch");
  EXPECT_EQ(first.pipeline.pairs_done, 3u);
  EXPECT_EQ(first.pipeline.verified_pairs, 3u);
  EXPECT_GT(first.pipeline.inlier_matches, 3u * 300u);
  EXPECT_GE(progress_calls, 1u);
  EXPECT_EQ(last_done, 3u);
  EXPECT_TRUE(warnings.empty());
  ASSERT_FALSE(notes.empty());
  EXPECT_NE(std::find_if(notes.begin(), notes.end(),
                         [](const std::string& n) { return n.rfind("Exact rematch: 3 of 3 pairs", 0) == 0; }),
            notes.end())
      << testing::PrintToString(notes);
  EXPECT_EQ(notes.back().rfind("Features: 3 image reads for 3 images", 0), 0u) << notes.back();

  notes.clear();
  const colmap::MatchingSummary second = colmap::MatchExhaustive(path_, options_, callbacks);
  EXPECT_EQ(second.pairs_skipped, 3u);
  EXPECT_TRUE(second.matcher_name.empty());
  EXPECT_EQ(second.pipeline.pairs_done, 0u);
  EXPECT_EQ(second.pairs_requested, 3u);
}

TEST_F(SceneDatabase, DefaultsChooseTablesAndMatcherAndSaySo) {
  std::vector<std::string> notes;
  colmap::MatchingCallbacks callbacks;
  callbacks.info = [&](const std::string& text) { notes.push_back(text); };
  const colmap::MatchingSummary summary = colmap::MatchExhaustive(path_, options_, callbacks);
  EXPECT_EQ(summary.pipeline.pairs_done, 3u);
  EXPECT_EQ(summary.pipeline.verified_pairs, 3u);
  const auto starts = [&](const std::string& prefix) {
    return std::find_if(notes.begin(), notes.end(),
                        [&](const std::string& n) { return n.rfind(prefix, 0) == 0; }) != notes.end();
  };
  // Hundreds of features per image: the reference's 8 x 7. On the CPU auto
  // is the cascade with the rematch of the pairs near the threshold only,
  // so the tables are chosen for the cascade's own matches.
  EXPECT_TRUE(starts("Hash tables: 8 x 7 bits (chosen for ")) << testing::PrintToString(notes);
  EXPECT_TRUE(starts("Matcher: cascade, exact rematch of pairs with 12 to 63 cascade matches (CPU rule)"))
      << testing::PrintToString(notes);
  EXPECT_EQ(summary.matcher_name, "cpu-cascade+exact-rematch");
  // The resolved run carries the window.
  EXPECT_EQ(summary.run.options.cashash.matcher, MatcherType::kCascade);
  EXPECT_EQ(summary.run.options.cashash.exact_rematch_min_matches, kCpuRematchWindowMin);
  EXPECT_EQ(summary.run.options.cashash.exact_rematch_max_matches, kCpuRematchWindowMax);
  EXPECT_EQ(summary.run.options.cashash.tau, kCascadeTauForPrecision);
}

// Every column of every row of `table`, in pair order, as text.
std::vector<std::string> TableRows(const std::string& path, const std::string& table) {
  sqlite3* db = nullptr;
  EXPECT_EQ(sqlite3_open_v2(path.c_str(), &db, SQLITE_OPEN_READONLY, nullptr), SQLITE_OK);
  sqlite3_stmt* stmt = nullptr;
  const std::string sql = "SELECT * FROM " + table + " ORDER BY pair_id";
  EXPECT_EQ(sqlite3_prepare_v2(db, sql.c_str(), -1, &stmt, nullptr), SQLITE_OK) << sql;
  std::vector<std::string> rows;
  while (sqlite3_step(stmt) == SQLITE_ROW) {
    std::string row;
    for (int c = 0; c < sqlite3_column_count(stmt); ++c) {
      const void* bytes = sqlite3_column_blob(stmt, c);
      row += std::to_string(sqlite3_column_bytes(stmt, c)) + ":";
      if (bytes != nullptr) row.append(static_cast<const char*>(bytes), sqlite3_column_bytes(stmt, c));
      row += "|";
    }
    rows.push_back(row);
  }
  sqlite3_finalize(stmt);
  sqlite3_close(db);
  return rows;
}

// The default decides from the data, not the clock: two runs over the
// same database write the same rows.
TEST_F(SceneDatabase, TheDefaultWritesTheSameRowsOnEveryRun) {
  colmap::MatchExhaustive(path_, options_);
  const std::vector<std::string> matches = TableRows(path_, "matches");
  const std::vector<std::string> geometries = TableRows(path_, "two_view_geometries");
  ASSERT_EQ(matches.size(), 3u);
  ASSERT_EQ(geometries.size(), 3u);
  colmap::MatcherCommandOptions again = options_;
  again.overwrite = true;
  for (int run = 0; run < 2; ++run) {
    colmap::MatchExhaustive(path_, again);
    EXPECT_EQ(TableRows(path_, "matches"), matches) << "run " << run;
    EXPECT_EQ(TableRows(path_, "two_view_geometries"), geometries) << "run " << run;
  }
}

TEST_F(SceneDatabase, TimeOutsideThePipelineIsReportedPhaseByPhase) {
  const auto start = std::chrono::steady_clock::now();
  const colmap::MatchingSummary summary = colmap::MatchExhaustive(path_, options_);
  const double call_seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  std::vector<std::string> names;
  double phase_seconds = 0;
  for (const PhaseClock::Phase& phase : summary.phases_outside_pipeline) {
    names.push_back(phase.name);
    phase_seconds += phase.seconds;
  }
  // The phases and the pipeline are disjoint stretches of the call: none is
  // counted twice, so together they fit in the call's own time.
  EXPECT_GT(summary.pipeline.seconds_total, 0.0);
  EXPECT_LE(phase_seconds + summary.pipeline.seconds_total, call_seconds);
  // Before the pipeline, in the order the run builds itself, and after it,
  // in the order it is taken apart; the pipeline's own time is not a phase.
  const std::vector<std::string> expected = {"opening the database",
                                             "reading the feature counts",
                                             "starting the GPU and sizing the run",
                                             "finding the pairs left to match",
                                             "starting the feature reader",
                                             "waiting for the hashing mean",
                                             "making the matcher",
                                             "opening the database for writing",
                                             "making the verifier",
                                             "starting the pipeline",
                                             "freeing the verifier",
                                             "closing the database",
                                             "freeing the matcher",
                                             "stopping the feature reader"};
  EXPECT_EQ(names, expected);
  double outside = 0.0;
  for (const PhaseClock::Phase& phase : summary.phases_outside_pipeline) outside += phase.seconds;
  EXPECT_GT(summary.pipeline.seconds_total, 0.0);
  EXPECT_LT(outside, 60.0);
}

TEST_F(SceneDatabase, PairsByNameMatchOnceAndNameUnknownImages) {
  const colmap::MatchingSummary summary =
      colmap::MatchPairs(path_, {{"view1.jpg", "view3.jpg"}, {"view3.jpg", "view1.jpg"}}, options_);
  EXPECT_EQ(summary.pairs_requested, 1u);
  EXPECT_EQ(summary.pipeline.verified_pairs, 1u);

  try {
    colmap::MatchPairs(path_, {{"view1.jpg", "view2.jpg"}, {"view2.jpg", "nope.jpg"}}, options_);
    FAIL() << "accepted an unknown image";
  } catch (const std::runtime_error& e) {
    EXPECT_EQ(std::string(e.what()), "image pair 1: image 'nope.jpg' is not in table images");
  }
}

TEST_F(SceneDatabase, OptionErrorsCarryTheCommandLineMessage) {
  options_.block_size = 1;
  try {
    colmap::MatchExhaustive(path_, options_);
    FAIL() << "accepted block_size 1";
  } catch (const std::invalid_argument& e) {
    EXPECT_EQ(std::string(e.what()), "--ExhaustiveMatching.block_size must be >= 2");
  }
  options_.block_size = 0;  // chosen for the run
  EXPECT_THROW(colmap::MatchExhaustive(path_ + ".missing", options_), std::runtime_error);
}

// The process environment, as name=value lines in order.
std::vector<std::string> Environment() {
  std::vector<std::string> lines;
  for (char** entry = environ; *entry != nullptr; ++entry) lines.emplace_back(*entry);
  return lines;
}

// --max_gpu_memory reaches the run's matchers (ResolvedRun::
// gpu_memory_budget_bytes, which CreateMatcherForRun hands to each GPU
// matcher's config) from every entry point, and from each call anew; the
// environment is not how it gets there: a run leaves it untouched while
// its threads start (setenv beside the mean-descriptor thread's reads was
// a data race).
TEST_F(SceneDatabase, MaxGpuMemoryReachesTheMatchersOfEveryEntryPointAndCall) {
  const std::vector<std::string> environment = Environment();
  const std::string pair_list = (dir_ / "pairs.txt").string();
  {
    std::ofstream file(pair_list);
    file << "view1.jpg view2.jpg\nview2.jpg view3.jpg\n";
  }
  options_.overwrite = true;
  for (const auto& [given, bytes] : {std::make_pair("512M", size_t{512} << 20), std::make_pair("1G", size_t{1} << 30),
                                     std::make_pair("", size_t{0})}) {
    SCOPED_TRACE(std::string("--max_gpu_memory '") + given + "'");
    options_.max_gpu_memory = given;
    EXPECT_EQ(colmap::MatchExhaustive(path_, options_).run.gpu_memory_budget_bytes, bytes);
    EXPECT_EQ(colmap::MatchPairs(path_, {{"view1.jpg", "view3.jpg"}}, options_).run.gpu_memory_budget_bytes, bytes);
    EXPECT_EQ(colmap::MatchPairList(path_, pair_list, options_).run.gpu_memory_budget_bytes, bytes);
  }
  EXPECT_EQ(Environment(), environment);
}

// Python's options are the command line's struct with the same defaults: an
// exhaustive run from the library sizes its blocks from memory and keeps a
// rematch threshold that was set, even the default's value.
TEST_F(SceneDatabase, LibraryRunsResolveAsTheCommandLineDoes) {
  const colmap::MatchingSummary summary = colmap::MatchExhaustive(path_, options_);
  EXPECT_EQ(summary.run.options.block_size, summary.run.schedule.block_size);
  EXPECT_GT(summary.run.schedule.blocks_per_group, 0);
  EXPECT_GT(summary.run.max_host_bytes, 0u);
  EXPECT_EQ(summary.run.options.cashash.exact_rematch_min_matches, colmap::kDefaultRematchMinMatches);
  options_.overwrite = true;
  options_.cashash.exact_rematch_min_matches = 12;
  options_.block_size = 2;
  const colmap::MatchingSummary set = colmap::MatchExhaustive(path_, options_);
  EXPECT_EQ(set.run.options.cashash.exact_rematch_min_matches, 12);
  EXPECT_EQ(set.run.options.block_size, 2);
  EXPECT_EQ(set.run.schedule.block_size, 2);
}

}  // namespace
}  // namespace cashash
