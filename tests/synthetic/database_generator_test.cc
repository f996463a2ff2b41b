// generate_database: a valid COLMAP 3.8 database, the same for the same
// seed, exactly num_features per image, keypoints that are projections of
// the scene, neighbouring images that verify and far ones that do not.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <set>
#include <stdexcept>
#include <thread>

#include "cashash/base/pair_id.h"
#include "colmap_bridge/blob_codec.h"
#include "colmap_bridge/database.h"
#include "synthetic/database_generator.h"
#include "colmap_bridge/database_pipeline_io.h"
#include "colmap_bridge/position_priors.h"
#include "synthetic/generate_database_command.h"
#include "colmap_bridge/api/matching_api.h"
#include "synthetic/synthetic_street_scene.h"
#include "generated_database_support.h"

namespace cashash {
namespace {

using colmap::Database;
using colmap::DatabaseGeneratorOptions;
using testing_support::ScratchDir;

class DatabaseGeneratorTest : public ::testing::Test {
 protected:
  void SetUp() override { testing_support::WriteRandomSourceDatabase(source_, 3, 2000); }

  DatabaseGeneratorOptions Options(const std::string& name, int num_images, int num_features) const {
    DatabaseGeneratorOptions o;
    o.database_path = scratch_.File(name);
    o.source_database_path = source_;
    o.num_images = num_images;
    o.num_features = num_features;
    o.random_seed = 5;
    return o;
  }

  ScratchDir scratch_{"generator_test"};
  std::string source_ = scratch_.File("source.db");
};

TEST_F(DatabaseGeneratorTest, PositionPriorsAreTheCameraCentres) {
  DatabaseGeneratorOptions o = Options("cartesian.db", 6, 50);
  o.position_priors = "cartesian";
  colmap::GenerateDatabase(o);
  SpatialPairingOptions read_options;
  read_options.is_gps = false;
  const std::vector<PositionPrior> cartesian =
      colmap::ReadPositionPriors(Database(o.database_path, true), read_options).priors;
  o = Options("gps.db", 6, 50);
  o.position_priors = "gps";
  colmap::GenerateDatabase(o);
  const std::vector<PositionPrior> gps =
      colmap::ReadPositionPriors(Database(o.database_path, true), SpatialPairingOptions()).priors;
  ASSERT_EQ(cartesian.size(), 6u);
  ASSERT_EQ(gps.size(), 6u);
  for (size_t k = 0; k + 1 < cartesian.size(); ++k) {
    // East along the street, one unit (metre) a camera, 0.15 of jitter.
    const Eigen::Vector3d step = cartesian[k + 1].position - cartesian[k].position;
    EXPECT_NEAR(step.x(), 1.0, 0.31);
    // The same step in GPS: its length in ECEF metres, heights included.
    const double metres = (GeodeticToEcef(gps[k + 1].position) - GeodeticToEcef(gps[k].position)).norm();
    EXPECT_NEAR(metres, step.norm(), 0.01);
    EXPECT_NEAR(gps[k].position.x(), 47.3769, 0.01);  // latitude, degrees
  }
  o = Options("bad.db", 2, 50);
  o.position_priors = "utm";
  EXPECT_NE(o.Check().find("--position_priors"), std::string::npos);
}

TEST_F(DatabaseGeneratorTest, WritesAValidColmapDatabaseWithExactlyTheFeatureCount) {
  const DatabaseGeneratorOptions o = Options("out.db", 7, 700);
  const colmap::GeneratorSummary summary = colmap::GenerateDatabase(o);
  EXPECT_EQ(summary.num_images, 7);
  EXPECT_EQ(summary.num_features, 7 * 700);
  EXPECT_EQ(summary.keypoint_columns, 6);
  // About 1 - distractor_ratio of the features are scene points.
  EXPECT_NEAR(static_cast<double>(summary.observed_features) / summary.num_features, 0.7, 0.02);

  // The reader the matcher uses accepts it (cameras, names, shapes checked).
  colmap::DatabaseFeatureSource source(o.database_path);
  ASSERT_EQ(source.images().size(), 7u);
  const Database& db = source.database();
  EXPECT_EQ(db.schema().user_version, 3800);
  EXPECT_FALSE(db.schema().descriptors_have_type);
  for (const Image& image : source.images()) {
    const ImageFeatures features = source.LoadFeatures(image.image_id);
    ASSERT_EQ(features.keypoints.size(), 700u) << image.name;
    ASSERT_EQ(features.descriptors.rows(), 700u) << image.name;
    EXPECT_EQ(db.KeypointColumns(image.image_id), 6);
    const Camera& camera = source.CameraOfImage(image.image_id);
    EXPECT_EQ(camera.model_id, 2);  // SIMPLE_RADIAL
    EXPECT_TRUE(camera.has_prior_focal_length);
    for (const Keypoint& kp : features.keypoints) {
      ASSERT_GE(kp.x, 0.f);
      ASSERT_LE(kp.x, camera.width);
      ASSERT_GE(kp.y, 0.f);
      ASSERT_LE(kp.y, camera.height);
    }
    // Stored as COLMAP stores SIFT: scaled to norm 512, so the norm is 512
    // where no value was capped at 255 and a little less where one was.
    for (size_t i = 0; i < features.descriptors.rows(); ++i) {
      const uint8_t* d = features.descriptors.row(i);
      double norm = 0;
      int max_value = 0;
      for (int k = 0; k < kDescriptorDim; ++k) {
        norm += static_cast<double>(d[k]) * d[k];
        max_value = std::max<int>(max_value, d[k]);
      }
      ASSERT_LE(std::sqrt(norm), 512.0 + 6.0);  // rounding
      if (max_value < 255) {
        ASSERT_GE(std::sqrt(norm), 512.0 - 6.0) << "row " << i;
      }
    }
  }
}

TEST_F(DatabaseGeneratorTest, SameSeedSameDatabaseOtherSeedOtherFeaturesAnyThreadCount) {
  DatabaseGeneratorOptions a = Options("a.db", 4, 300);
  DatabaseGeneratorOptions b = Options("b.db", 4, 300);
  DatabaseGeneratorOptions c = Options("c.db", 4, 300);
  c.random_seed = 6;
  // Threads and transactions do not change what is written.
  a.num_threads = 1;
  b.num_threads = 3;
  b.images_per_transaction = 3;
  colmap::GenerateDatabase(a);
  colmap::GenerateDatabase(b);
  colmap::GenerateDatabase(c);
  Database da(a.database_path, true), db(b.database_path, true), dc(c.database_path, true);
  for (image_t id = 1; id <= 4; ++id) {
    EXPECT_EQ(da.ReadDescriptors(id).data, db.ReadDescriptors(id).data);
    const Keypoints ka = da.ReadKeypoints(id), kb = db.ReadKeypoints(id);
    ASSERT_EQ(ka.size(), kb.size());
    for (size_t i = 0; i < ka.size(); ++i) {
      EXPECT_EQ(ka[i].x, kb[i].x);
      EXPECT_EQ(ka[i].y, kb[i].y);
    }
    EXPECT_NE(da.ReadDescriptors(id).data, dc.ReadDescriptors(id).data);
  }
}

// The feature cache loads with several threads at once (MaxConcurrentLoads):
// each call reads through its own pooled connection and returns what one
// thread alone reads.
TEST_F(DatabaseGeneratorTest, FeatureSourceLoadsFromSeveralThreadsAtOnce) {
  const DatabaseGeneratorOptions o = Options("concurrent.db", 6, 500);
  colmap::GenerateDatabase(o);
  colmap::DatabaseFeatureSource source(o.database_path);
  EXPECT_GT(source.MaxConcurrentLoads(), 1);
  std::map<image_t, ImageFeatures> alone;
  for (const Image& image : source.images()) alone[image.image_id] = source.LoadFeatures(image.image_id);
  constexpr int kThreads = 4;
  std::vector<std::map<image_t, ImageFeatures>> seen(kThreads);
  std::vector<std::thread> threads;
  for (int t = 0; t < kThreads; ++t) {
    threads.emplace_back([&, t]() {
      for (int round = 0; round < 5; ++round) {
        for (const Image& image : source.images()) seen[t][image.image_id] = source.LoadFeatures(image.image_id);
      }
    });
  }
  for (std::thread& thread : threads) thread.join();
  for (int t = 0; t < kThreads; ++t) {
    ASSERT_EQ(seen[t].size(), alone.size());
    for (const auto& [id, features] : alone) {
      EXPECT_EQ(seen[t][id].descriptors.data, features.descriptors.data) << "image " << id;
      ASSERT_EQ(seen[t][id].keypoints.size(), features.keypoints.size());
      for (size_t i = 0; i < features.keypoints.size(); ++i) {
        EXPECT_EQ(seen[t][id].keypoints[i].x, features.keypoints[i].x);
        EXPECT_EQ(seen[t][id].keypoints[i].y, features.keypoints[i].y);
      }
    }
  }
}

TEST(EncodeKeypointsTest, TwoFourAndSixColumnsRoundTripThroughTheDecoder) {
  Keypoint kp;
  kp.x = 10.5f;
  kp.y = 20.25f;
  const float scale = 3.f, angle = 0.7f;
  kp.a11 = scale * std::cos(angle);
  kp.a12 = -scale * std::sin(angle);
  kp.a21 = scale * std::sin(angle);
  kp.a22 = scale * std::cos(angle);
  for (int cols : {2, 4, 6}) {
    const std::vector<float> values = colmap::EncodeKeypoints({kp, kp}, cols);
    ASSERT_EQ(values.size(), 2u * cols);
    colmap::MatrixBlob blob;
    blob.rows = 2;
    blob.cols = cols;
    blob.data = values.data();
    blob.num_bytes = values.size() * sizeof(float);
    const Keypoint back = colmap::DecodeKeypoints(blob, "test")[1];
    EXPECT_EQ(back.x, kp.x);
    EXPECT_EQ(back.y, kp.y);
    if (cols == 2) continue;  // no shape stored
    EXPECT_NEAR(back.a11, kp.a11, 1e-5);
    EXPECT_NEAR(back.a12, kp.a12, 1e-5);
    EXPECT_NEAR(back.a21, kp.a21, 1e-5);
    EXPECT_NEAR(back.a22, kp.a22, 1e-5);
  }
  EXPECT_THROW(colmap::EncodeKeypoints({kp}, 3), colmap::DatabaseError);
}

// A 30-image street, small enough for the scene tests.
colmap::SyntheticStreetSceneOptions ThirtyImageStreet() {
  colmap::SyntheticStreetSceneOptions o;
  o.num_images = 30;
  o.points_per_cell = 50;
  o.random_seed = 3;
  return o;
}

TEST(SyntheticStreetSceneTest, ObservationsAreProjectionsOfTheScenePoints) {
  const colmap::SyntheticStreetSceneOptions o = ThirtyImageStreet();
  const colmap::SyntheticStreetScene scene(o);
  for (int k : {0, 14, 29}) {
    const std::vector<colmap::PointObservation> seen = scene.Observe(k);
    ASSERT_GT(seen.size(), 200u);
    for (const colmap::PointObservation& obs : seen) {
      const Eigen::Vector3d Xc = scene.Rotation(k) * (scene.Point(obs.point_index) - scene.Centre(k));
      EXPECT_NEAR(o.focal_length * Xc.x() / Xc.z() + 0.5 * o.image_width, obs.x, 1e-6);
      EXPECT_NEAR(o.focal_length * Xc.y() / Xc.z() + 0.5 * o.image_height, obs.y, 1e-6);
      EXPECT_NEAR(Xc.z(), obs.depth, 1e-9);
    }
  }
  // Neighbours share many points, far cameras none.
  auto shared = [&](int a, int b) {
    std::set<uint64_t> ids;
    for (const auto& obs : scene.Observe(a)) ids.insert(obs.point_index);
    size_t n = 0;
    for (const auto& obs : scene.Observe(b)) n += ids.count(obs.point_index);
    return n;
  };
  EXPECT_GT(shared(10, 11), scene.Observe(10).size() / 2);
  EXPECT_EQ(shared(0, 29), 0u);
}

// A seed names one street on every compiler: these draws once depended on
// the unspecified order in which a call's arguments are evaluated, so a
// clang build generated other cameras than a g++ build.
TEST(SyntheticStreetSceneTest, ASeedGivesTheSameCamerasOnEveryCompiler) {
  const colmap::SyntheticStreetScene scene(ThirtyImageStreet());
  const Eigen::Vector3d first(-0.14909699391747347, 0.028216579622629256, -0.0086092517778150416);
  const Eigen::Vector3d eighth(7.0633182987325007, -0.10164101456763759, 0.076377903850348525);
  EXPECT_LT((scene.Centre(0) - first).norm(), 1e-12) << scene.Centre(0).transpose();
  EXPECT_LT((scene.Centre(7) - eighth).norm(), 1e-12) << scene.Centre(7).transpose();
}

TEST_F(DatabaseGeneratorTest, NeighboursVerifyWithManyInliersFarImagesDoNot) {
  DatabaseGeneratorOptions o = Options("match.db", 26, 1024);
  colmap::GenerateDatabase(o);
  colmap::MatcherCommandOptions options;
  options.use_gpu = false;
  options.cashash.matcher = MatcherType::kBruteForce;  // exact: no hashing luck in a test
  colmap::MatchPairs(o.database_path,
                     {{"synthetic_000001.jpg", "synthetic_000002.jpg"},
                      {"synthetic_000001.jpg", "synthetic_000004.jpg"},
                      {"synthetic_000001.jpg", "synthetic_000026.jpg"}},
                     options);
  Database db(o.database_path, true);
  const TwoViewGeometry near = db.ReadTwoViewGeometry(1, 2);
  EXPECT_EQ(near.config, kCalibrated);
  EXPECT_GT(near.inlier_matches.size(), 400u);  // of about 700 scene points per image
  const TwoViewGeometry farther = db.ReadTwoViewGeometry(1, 4);
  EXPECT_EQ(farther.config, kCalibrated);
  EXPECT_GT(farther.inlier_matches.size(), 150u);
  EXPECT_LT(db.ReadTwoViewGeometry(1, 26).inlier_matches.size(), 15u);
}

TEST_F(DatabaseGeneratorTest, ErrorsNameTheOption) {
  auto error_of = [](const DatabaseGeneratorOptions& o) {
    try {
      colmap::GenerateDatabase(o);
    } catch (const std::exception& e) {
      return std::string(e.what());
    }
    return std::string();
  };
  DatabaseGeneratorOptions o = Options("err.db", 3, 100);
  o.num_images = 0;
  EXPECT_NE(error_of(o).find("--num_images"), std::string::npos);
  o = Options("err.db", 3, 100);
  o.num_features = 0;
  EXPECT_NE(error_of(o).find("--num_features"), std::string::npos);
  o = Options("err.db", 3, 100);
  o.camera_model = "FISHEYE";
  EXPECT_NE(error_of(o).find("--camera_model"), std::string::npos);
  o = Options("err.db", 3, 100);
  o.source_database_path = scratch_.File("missing.db");
  EXPECT_NE(error_of(o).find("--source_database_path"), std::string::npos);
  EXPECT_FALSE(std::filesystem::exists(o.database_path));  // nothing left behind
  o = Options("err.db", 3, 100);
  o.database_path = source_;
  EXPECT_NE(error_of(o).find("--database_path"), std::string::npos);
  o = Options("exists.db", 3, 100);
  colmap::GenerateDatabase(o);
  EXPECT_NE(error_of(o).find("exists already"), std::string::npos);
}

TEST_F(DatabaseGeneratorTest, CommandLineWritesTheDatabaseAndNamesBadOptions) {
  const std::string out = scratch_.File("cli.db");
  auto run = [](std::vector<std::string> args, std::string* err) {
    std::vector<const char*> argv = {"generate_database"};
    for (const std::string& a : args) argv.push_back(a.c_str());
    ::testing::internal::CaptureStdout();
    ::testing::internal::CaptureStderr();
    const int code = colmap::RunGenerateDatabase(static_cast<int>(argv.size()), argv.data());
    ::testing::internal::GetCapturedStdout();
    *err = ::testing::internal::GetCapturedStderr();
    return code;
  };
  std::string err;
  EXPECT_EQ(run({"--database_path", out, "--source_database_path", source_, "--num_images", "3", "--num_features",
                 "200", "--ground_truth_path", scratch_.File("gt")},
                &err),
            0)
      << err;
  // The true cameras as a COLMAP text model: one pose line and one empty
  // line per image, one camera per image.
  std::ifstream images(scratch_.File("gt") + "/images.txt"), cameras(scratch_.File("gt") + "/cameras.txt");
  std::string line;
  std::vector<std::string> image_lines, camera_lines;
  while (std::getline(images, line)) {
    if (!line.empty() && line[0] != '#') image_lines.push_back(line);
  }
  while (std::getline(cameras, line)) {
    if (!line.empty() && line[0] != '#') camera_lines.push_back(line);
  }
  ASSERT_EQ(image_lines.size(), 3u);
  EXPECT_NE(image_lines[2].find(" 3 synthetic_000003.jpg"), std::string::npos) << image_lines[2];
  ASSERT_EQ(camera_lines.size(), 3u);
  EXPECT_EQ(camera_lines[0].rfind("1 SIMPLE_RADIAL 1600 1200 1920 800 600 0", 0), 0u) << camera_lines[0];
  EXPECT_TRUE(std::filesystem::exists(scratch_.File("gt") + "/points3D.txt"));
  {
    Database db(out, true);
    EXPECT_EQ(db.ReadAllImages().size(), 3u);
    EXPECT_EQ(db.NumDescriptors(3), 200u);
  }
  EXPECT_EQ(run({"--database_path", scratch_.File("cli2.db"), "--num_images", "3"}, &err), 1);
  EXPECT_NE(err.find("--source_database_path is required"), std::string::npos) << err;
  EXPECT_EQ(run({"--database_path", scratch_.File("cli2.db"), "--num_imagez", "3"}, &err), 1);
  EXPECT_NE(err.find("num_imagez"), std::string::npos) << err;
  EXPECT_EQ(run({"--database_path", out, "--source_database_path", source_, "--num_images", "3"}, &err), 1);
  EXPECT_NE(err.find("--database_path"), std::string::npos) << err;
}

}  // namespace
}  // namespace cashash
