// Position priors where each schema keeps them: the prior_t* columns of
// table images (COLMAP 3.8), pose_priors keyed by image_id (3.10 to 3.13)
// and pose_priors of COLMAP 4.x, checked against pycolmap's own reading.
#include "colmap_bridge/position_priors.h"

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <memory>
#include <sstream>
#include <string>

#include <gtest/gtest.h>

#include "colmap_bridge/colmap38_schema.h"
#include "colmap_bridge/sqlite_statement.h"
#include "generated_database_support.h"

namespace cashash {
namespace colmap {
namespace {

bool HavePycolmap() {
  static const bool have = std::system("python3 -c 'import pycolmap' > /dev/null 2>&1") == 0;
  return have;
}

const std::string kScript = std::string(CASHASH_SOURCE_DIR) + "/scripts/make_colmap4_database.py";

std::string Output(const std::string& command) {
  std::string text;
  FILE* pipe = popen(command.c_str(), "r");
  if (pipe == nullptr) return text;
  char buffer[4096];
  size_t n = 0;
  while ((n = fread(buffer, 1, sizeof(buffer), pipe)) > 0) text.append(buffer, n);
  pclose(pipe);
  return text;
}

// Three images a.jpg, b.jpg, c.jpg with cameras 1, 2, 3.
void AddImages(Database& db) {
  Camera camera;
  camera.model_id = 0;
  camera.width = 100;
  camera.height = 100;
  camera.params = {100, 50, 50};
  for (const char* name : {"a.jpg", "b.jpg", "c.jpg"}) db.WriteImage(name, db.WriteCamera(camera));
}

PositionPrior Prior(image_t image_id, double x, double y, double z, PriorCoordinateSystem system) {
  PositionPrior prior;
  prior.image_id = image_id;
  prior.position = Eigen::Vector3d(x, y, z);
  prior.coordinate_system = system;
  return prior;
}

const PositionPrior* Find(const DatabasePositionPriors& read, image_t image_id) {
  for (const PositionPrior& prior : read.priors) {
    if (prior.image_id == image_id) return &prior;
  }
  return nullptr;
}

class PositionPriorsTest : public testing::Test {
 protected:
  testing_support::ScratchDir dir_{"position_priors"};
};

TEST_F(PositionPriorsTest, Colmap38ColumnsWithTheirZeroRule) {
  const std::string path = dir_.File("colmap38.db");
  CreateColmap38Database(path);
  Database db(path);
  AddImages(db);
  WritePositionPrior(db, 1, 1, Prior(1, 47.5, 8.5, 400, PriorCoordinateSystem::kWgs84));
  WritePositionPrior(db, 2, 2, Prior(2, 0, 0, 12, PriorCoordinateSystem::kWgs84));  // 3.8: x = y = 0 is none
  SpatialPairingOptions options;
  DatabasePositionPriors read = ReadPositionPriors(db, options);
  EXPECT_NE(read.source.find("prior_tx"), std::string::npos);
  ASSERT_EQ(read.priors.size(), 1u);
  EXPECT_EQ(read.priors[0].image_id, 1u);
  EXPECT_EQ(read.priors[0].position, Eigen::Vector3d(47.5, 8.5, 400));
  EXPECT_EQ(read.priors[0].coordinate_system, PriorCoordinateSystem::kWgs84);
  // With heights compared, 3.8 takes (0, 0, 12); is_gps 0 reads Cartesian.
  options.ignore_z = false;
  options.is_gps = false;
  read = ReadPositionPriors(db, options);
  ASSERT_EQ(read.priors.size(), 2u);
  ASSERT_NE(Find(read, 2), nullptr);
  EXPECT_EQ(Find(read, 2)->position, Eigen::Vector3d(0, 0, 12));
  EXPECT_EQ(Find(read, 2)->coordinate_system, PriorCoordinateSystem::kCartesian);
  EXPECT_EQ(Find(read, 3), nullptr);
}

TEST_F(PositionPriorsTest, PosePriorsKeyedByImageIdOf310) {
  const std::string path = dir_.File("colmap310.db");
  CreateColmap38Database(path);
  Database db(path);
  AddImages(db);
  db.UseStatement(
      "CREATE TABLE pose_priors (image_id INTEGER PRIMARY KEY NOT NULL, position BLOB, coordinate_system INTEGER "
      "NOT NULL, position_covariance BLOB)",
      [](SqliteStatement& s) { s.Execute(); });
  Database reopened(path);
  WritePositionPrior(reopened, 3, 3, Prior(3, 1, 2, 3, PriorCoordinateSystem::kCartesian));
  const DatabasePositionPriors read = ReadPositionPriors(reopened, SpatialPairingOptions());
  EXPECT_EQ(read.source, "table pose_priors");
  ASSERT_EQ(read.priors.size(), 1u);
  EXPECT_EQ(read.priors[0].image_id, 3u);
  EXPECT_EQ(read.priors[0].position, Eigen::Vector3d(1, 2, 3));
  EXPECT_EQ(read.priors[0].coordinate_system, PriorCoordinateSystem::kCartesian);
}

TEST_F(PositionPriorsTest, Colmap4PosePriorsAsPycolmapReadsThem) {
  if (!HavePycolmap()) GTEST_SKIP() << "pycolmap is not installed";
  const std::string path = dir_.File("colmap4.db");
  ASSERT_EQ(std::system(("python3 '" + kScript + "' '" + path + "'").c_str()), 0);
  {
    Database db(path);
    AddImages(db);
    WritePositionPrior(db, 1, 1, Prior(1, 47.25, 8.75, 410.5, PriorCoordinateSystem::kWgs84));
    WritePositionPrior(db, 3, 3, Prior(3, -4.5, 2.25, 1, PriorCoordinateSystem::kCartesian));
    WritePositionPrior(db, 3, 3, Prior(3, -4.5, 2.25, 7, PriorCoordinateSystem::kCartesian));  // replaces
    const DatabasePositionPriors read = ReadPositionPriors(db, SpatialPairingOptions());
    ASSERT_EQ(read.priors.size(), 2u);
    ASSERT_NE(Find(read, 3), nullptr);
    EXPECT_EQ(Find(read, 3)->position, Eigen::Vector3d(-4.5, 2.25, 7));
  }
  // pycolmap sees the same priors: image, coordinate system, position.
  const std::string text = Output(
      "python3 -c \"import pycolmap\ndb = pycolmap.Database.open('" + path +
      "')\nfor p in sorted(db.read_all_pose_priors(), key=lambda p: p.corr_data_id.id):\n"
      "    print(p.corr_data_id.id, int(p.coordinate_system), *p.position)\"");
  EXPECT_EQ(text, "1 0 47.25 8.75 410.5\n3 1 -4.5 2.25 7.0\n");
}

TEST_F(PositionPriorsTest, BadRowsAreNamed) {
  const std::string path = dir_.File("bad.db");
  CreateColmap38Database(path);
  {
    Database db(path);
    AddImages(db);
    db.UseStatement(
        "CREATE TABLE pose_priors (image_id INTEGER NOT NULL, position BLOB, coordinate_system INTEGER NOT NULL)",
        [](SqliteStatement& s) { s.Execute(); });
  }
  Database db(path);
  const double two[2] = {1, 2};
  db.UseStatement("INSERT INTO pose_priors VALUES (2, ?, 1)", [&](SqliteStatement& s) {
    s.BindBlob(1, two, sizeof(two));
    s.Execute();
  });
  try {
    ReadPositionPriors(db, SpatialPairingOptions());
    ADD_FAILURE() << "a 16-byte position was read";
  } catch (const DatabaseError& error) {
    EXPECT_NE(std::string(error.what()).find("image 2"), std::string::npos) << error.what();
  }
  db.UseStatement("DELETE FROM pose_priors", [](SqliteStatement& s) { s.Execute(); });
  WritePositionPrior(db, 1, 1, Prior(1, 1, 2, 3, PriorCoordinateSystem::kCartesian));
  db.UseStatement("INSERT INTO pose_priors VALUES (1, NULL, 1)", [](SqliteStatement& s) { s.Execute(); });
  try {
    ReadPositionPriors(db, SpatialPairingOptions());
    ADD_FAILURE() << "two priors of one image were read";
  } catch (const DatabaseError& error) {
    EXPECT_NE(std::string(error.what()).find("two priors of image 1"), std::string::npos) << error.what();
  }
}

TEST_F(PositionPriorsTest, NoPlaceForPriorsIsAnError) {
  const std::string path = dir_.File("bare.db");
  CreateColmap38Database(path);
  Database db(path);
  db.UseStatement("ALTER TABLE images DROP COLUMN prior_tx", [](SqliteStatement& s) { s.Execute(); });
  Database reopened(path);
  try {
    ReadPositionPriors(reopened, SpatialPairingOptions());
    ADD_FAILURE() << "priors read from nowhere";
  } catch (const DatabaseError& error) {
    EXPECT_NE(std::string(error.what()).find("no position priors"), std::string::npos) << error.what();
  }
}

}  // namespace
}  // namespace colmap
}  // namespace cashash
