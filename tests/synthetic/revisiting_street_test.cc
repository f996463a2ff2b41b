// A street that returns to its start (revisit_images): the last K images
// stand near the first K places again and see the points seen there, the
// street before them is unchanged, and the option is checked by name.
#include <gtest/gtest.h>

#include <set>
#include <stdexcept>
#include <string>
#include <vector>

#include "colmap_bridge/database.h"
#include "colmap_bridge/position_priors.h"
#include "generated_database_support.h"
#include "synthetic/database_generator.h"
#include "synthetic/generate_database_command.h"
#include "synthetic/synthetic_street_scene.h"

namespace cashash {
namespace {

using colmap::SyntheticStreetScene;
using colmap::SyntheticStreetSceneOptions;

constexpr int kPlaces = 24;   // images of the first drive
constexpr int kRevisits = 8;  // images that drive its start again

SyntheticStreetSceneOptions Street(int num_images, int revisit_images) {
  SyntheticStreetSceneOptions o;
  o.num_images = num_images;
  o.revisit_images = revisit_images;
  o.points_per_cell = 50;
  o.random_seed = 3;
  return o;
}

std::set<uint64_t> PointsSeen(const SyntheticStreetScene& scene, int image_index) {
  std::set<uint64_t> ids;
  for (const colmap::PointObservation& obs : scene.Observe(image_index)) ids.insert(obs.point_index);
  return ids;
}

// Shared points over the points either image sees.
double SharedShare(const std::set<uint64_t>& a, const std::set<uint64_t>& b) {
  size_t shared = 0;
  for (uint64_t id : a) shared += b.count(id);
  return static_cast<double>(shared) / static_cast<double>(a.size() + b.size() - shared);
}

TEST(RevisitingStreetTest, RevisitingImagesSeeMostlyThePointsOfTheStart) {
  const SyntheticStreetScene scene(Street(kPlaces + kRevisits, kRevisits));
  for (int r = 0; r < kRevisits; ++r) {
    const int k = kPlaces + r;
    EXPECT_EQ(scene.StreetPlace(k), r);
    const std::set<uint64_t> revisit = PointsSeen(scene, k), first = PointsSeen(scene, r);
    ASSERT_GT(revisit.size(), 200u);
    // Their own jitter (0.15 along, 0.3 in depth, 4 degrees of yaw) moves
    // the view a little: most points, not all, are the counterpart's (0.68
    // to 0.94 of them on this street; yaws 8 degrees apart on a view of 45
    // leave about 0.7).
    EXPECT_GT(SharedShare(revisit, first), 0.5) << "image " << k;
    EXPECT_LT((scene.Centre(k) - scene.Centre(r)).norm(), 0.8) << "image " << k;
    // Not a duplicate: a pose of its own.
    EXPECT_GT((scene.Centre(k) - scene.Centre(r)).norm(), 1e-6) << "image " << k;
    // The last image of the first drive is far from the start: nothing shared.
    EXPECT_EQ(SharedShare(revisit, PointsSeen(scene, kPlaces - 1)), 0.0) << "image " << k;
  }
}

TEST(RevisitingStreetTest, TheFirstDriveIsTheStreetWithoutRevisits) {
  // Points come from cells and images from their own streams, so the
  // revisits change nothing before them.
  const SyntheticStreetScene with(Street(kPlaces + kRevisits, kRevisits));
  const SyntheticStreetScene without(Street(kPlaces, 0));
  EXPECT_EQ(with.num_cells(), without.num_cells());
  for (int k : {0, 7, kPlaces - 1}) {
    EXPECT_EQ(with.StreetPlace(k), k);
    EXPECT_EQ(with.Centre(k), without.Centre(k));
    EXPECT_EQ(with.Rotation(k), without.Rotation(k));
    EXPECT_EQ(PointsSeen(with, k), PointsSeen(without, k));
  }
}

TEST(RevisitingStreetTest, SceneRefusesRevisitsOutsideTheImages) {
  EXPECT_THROW(SyntheticStreetScene(Street(5, 5)), std::invalid_argument);
  EXPECT_THROW(SyntheticStreetScene(Street(5, -1)), std::invalid_argument);
  EXPECT_NO_THROW(SyntheticStreetScene(Street(5, 4)));
}

class RevisitingDatabaseTest : public ::testing::Test {
 protected:
  void SetUp() override { testing_support::WriteRandomSourceDatabase(source_, 2, 400); }

  colmap::DatabaseGeneratorOptions Options(const std::string& name) const {
    colmap::DatabaseGeneratorOptions o;
    o.database_path = scratch_.File(name);
    o.source_database_path = source_;
    o.num_images = 12;
    o.revisit_images = 4;
    o.num_features = 100;
    o.num_threads = 1;
    return o;
  }

  testing_support::ScratchDir scratch_{"revisiting_street"};
  std::string source_ = scratch_.File("source.db");
};

TEST_F(RevisitingDatabaseTest, PriorsOfRevisitingImagesLieAtTheStart) {
  colmap::DatabaseGeneratorOptions o = Options("priors.db");
  o.position_priors = "cartesian";
  colmap::GenerateDatabase(o);
  SpatialPairingOptions read_options;
  read_options.is_gps = false;
  const std::vector<PositionPrior> priors =
      colmap::ReadPositionPriors(colmap::Database(o.database_path, true), read_options).priors;
  ASSERT_EQ(priors.size(), 12u);
  for (int r = 0; r < 4; ++r) {
    // Image 9 + r (1-based) returns to image 1 + r; image 8 ends the first drive.
    EXPECT_LT((priors[8 + r].position - priors[r].position).norm(), 0.8) << "image " << 9 + r;
    EXPECT_GT((priors[8 + r].position - priors[7].position).norm(), 3.0) << "image " << 9 + r;
  }
}

TEST_F(RevisitingDatabaseTest, BadRevisitCountsNameTheOption) {
  colmap::DatabaseGeneratorOptions o = Options("bad.db");
  o.revisit_images = 12;
  EXPECT_NE(o.Check().find("--revisit_images"), std::string::npos) << o.Check();
  o.revisit_images = -1;
  EXPECT_NE(o.Check().find("--revisit_images"), std::string::npos) << o.Check();
  o.revisit_images = 11;
  EXPECT_EQ(o.Check(), "");

  const std::string out = scratch_.File("cli.db");
  std::vector<const char*> argv = {"generate_database", "--database_path", out.c_str(), "--source_database_path",
                                   source_.c_str(), "--num_images", "3", "--revisit_images", "3"};
  ::testing::internal::CaptureStdout();
  ::testing::internal::CaptureStderr();
  const int code = colmap::RunGenerateDatabase(static_cast<int>(argv.size()), argv.data());
  ::testing::internal::GetCapturedStdout();
  const std::string err = ::testing::internal::GetCapturedStderr();
  EXPECT_EQ(code, 1);
  EXPECT_NE(err.find("--revisit_images"), std::string::npos) << err;
}

}  // namespace
}  // namespace cashash
