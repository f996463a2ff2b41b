// `cashash sequential_matcher --SequentialMatching.overlap 10` on a generated
// street that returns to its start (generate_database --revisit_images):
// with loop detection it matches COLMAP's sequential pairs plus the loop
// pairs of its queries, and the loops close (every revisiting image
// verifies with an image of the start); without it none does.
#include <algorithm>
#include <cstdlib>
#include <set>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "cashash/base/pair_id.h"
#include "cashash/pipeline/sequential_pairs.h"
#include "colmap_bridge/commands/matching_commands.h"
#include "colmap_bridge/database.h"
#include "colmap_bridge/sqlite_statement.h"
#include "generated_database_support.h"
#include "pair_id_sets.h"
#include "synthetic/database_generator.h"

namespace cashash {
namespace colmap {
namespace {

// The first drive has kPlaces images, then kRevisits images drive its first
// places again. With quadratic overlap (COLMAP's default) the sequential
// pairs reach 1, 2, 4, ..., 512 images on: from a revisiting image at place
// p, 32 images back is place p + 16 of the first drive, beyond the ten or so
// places an image shares points with, and 64 back is before the first image.
// So the sequential pairs alone never close the loop, as on a long drive.
constexpr int kPlaces = 48;
constexpr int kRevisits = 12;
constexpr int kImages = kPlaces + kRevisits;
// Every 5th image asks for its 10 most similar images: queries at the start
// (0, 5, 10) and among the revisits (50, 55) can find the other drive.
// COLMAP's 10 and 50 also close the loops here, but 50 images are most of
// this street, which would not show that the retrieval finds them.
constexpr int kLoopPeriod = 5;
constexpr int kLoopImages = 10;
// Images this many places apart or fewer see common points.
constexpr int kSharedPlaces = 10;

// The place along the street of image index k (0-based, name order).
int PlaceOf(int k) { return k < kPlaces ? k : k - kPlaces; }

int IndexOf(image_t image_id) { return static_cast<int>(image_id) - 1; }  // ids follow name order

std::set<pair_t> PairIdsOf(const std::string& path, const std::string& sql) {
  std::set<pair_t> ids;
  const Database db(path, /*read_only=*/true);
  db.UseStatement(sql, [&](SqliteStatement& s) {
    while (s.Step()) ids.insert(static_cast<pair_t>(s.ColumnInt64(0)));
  });
  return ids;
}

// A pair of a revisiting image and an image of the first drive near its
// place: what closing the loop verifies.
bool ClosesTheLoop(pair_t pair_id) {
  const auto [image1, image2] = PairIdToImagePair(pair_id);
  const int a = std::min(IndexOf(image1), IndexOf(image2));
  const int b = std::max(IndexOf(image1), IndexOf(image2));
  return a < kPlaces && b >= kPlaces && std::abs(PlaceOf(a) - PlaceOf(b)) <= kSharedPlaces;
}

class SequentialLoopClosure : public testing::Test {
 protected:
  void SetUp() override {
    testing_support::WriteRandomSourceDatabase(dir_.File("source.db"), 2, 400);
    DatabaseGeneratorOptions generator;
    generator.database_path = path_;
    generator.source_database_path = dir_.File("source.db");
    generator.num_images = kImages;
    generator.revisit_images = kRevisits;
    generator.num_features = 200;
    generator.num_threads = 2;
    GenerateDatabase(generator);
  }

  // Runs the command as the shell would, its output captured.
  int RunSequentialMatcher(bool loop_detection) {
    const std::vector<std::string> args = {
        "sequential_matcher", "--database_path", path_, "--FeatureMatching.use_gpu", "0",
        "--FeatureMatching.num_threads", "2", "--SequentialMatching.overlap", "10",
        "--SequentialMatching.loop_detection", loop_detection ? "1" : "0",
        "--SequentialMatching.loop_detection_period", std::to_string(kLoopPeriod),
        "--SequentialMatching.loop_detection_num_images", std::to_string(kLoopImages)};
    std::vector<const char*> argv;
    for (const std::string& arg : args) argv.push_back(arg.c_str());
    testing::internal::CaptureStdout();
    testing::internal::CaptureStderr();
    const int code = colmap::RunSequentialMatcher(static_cast<int>(argv.size()), argv.data());
    output_ = testing::internal::GetCapturedStdout() + testing::internal::GetCapturedStderr();
    return code;
  }

  // COLMAP's sequential pairs (no loops) with overlap 10, quadratic.
  std::set<pair_t> SequentialPairIds() const {
    std::vector<SequenceImage> images;
    for (const Image& image : Database(path_, /*read_only=*/true).ReadAllImages()) {
      images.push_back({image.image_id, image.name, image.camera_id, 0});
    }
    SequentialPairingOptions options;
    options.overlap = 10;
    return testing_support::PairIds(SequentialPairs(images, options));
  }

  std::set<pair_t> Matched() const { return PairIdsOf(path_, "SELECT pair_id FROM matches"); }
  std::set<pair_t> Verified() const {
    return PairIdsOf(path_, "SELECT pair_id FROM two_view_geometries WHERE config >= 2");
  }

  testing_support::ScratchDir dir_{"sequential_loop_closure"};
  std::string path_ = dir_.File("street.db");
  std::string output_;
};

TEST_F(SequentialLoopClosure, LoopDetectionClosesTheLoopsOfAStreetThatReturns) {
  ASSERT_EQ(RunSequentialMatcher(true), EXIT_SUCCESS) << output_;
  const std::set<pair_t> matched = Matched(), verified = Verified(), sequential = SequentialPairIds();
  // COLMAP's sequential pairs, every one of them...
  for (pair_t id : sequential) EXPECT_EQ(matched.count(id), 1u) << "sequential pair " << id << " not matched";
  // ...plus loop pairs, each of a query (every kLoopPeriod-th image).
  size_t loop_pairs = 0;
  for (pair_t id : matched) {
    if (sequential.count(id)) continue;
    ++loop_pairs;
    const auto [image1, image2] = PairIdToImagePair(id);
    EXPECT_TRUE(IndexOf(image1) % kLoopPeriod == 0 || IndexOf(image2) % kLoopPeriod == 0) << "pair " << id;
  }
  EXPECT_GT(loop_pairs, 0u);
  // The loops close: each revisiting image verifies with an image of the
  // first drive near its place, its counterpart at the same place for some.
  std::set<int> closed;
  size_t counterparts = 0;
  for (pair_t id : verified) {
    if (!ClosesTheLoop(id)) continue;
    const auto [image1, image2] = PairIdToImagePair(id);
    const int revisit = std::max(IndexOf(image1), IndexOf(image2));
    closed.insert(revisit);
    if (std::abs(IndexOf(image1) - IndexOf(image2)) == kPlaces) ++counterparts;
  }
  EXPECT_EQ(closed.size(), static_cast<size_t>(kRevisits)) << output_;
  EXPECT_GT(counterparts, 0u);
  // And nothing closes falsely: pairs across the loop far from each other
  // do not verify.
  for (pair_t id : verified) {
    const auto [image1, image2] = PairIdToImagePair(id);
    const int a = std::min(IndexOf(image1), IndexOf(image2)), b = std::max(IndexOf(image1), IndexOf(image2));
    if (a < kPlaces && b >= kPlaces) {
      EXPECT_TRUE(ClosesTheLoop(id)) << "images " << a << " and " << b;
    }
  }
}

TEST_F(SequentialLoopClosure, WithoutLoopDetectionTheLoopStaysOpen) {
  ASSERT_EQ(RunSequentialMatcher(false), EXIT_SUCCESS) << output_;
  EXPECT_EQ(Matched(), SequentialPairIds());
  for (pair_t id : Matched()) EXPECT_FALSE(ClosesTheLoop(id)) << "pair " << id;
}

}  // namespace
}  // namespace colmap
}  // namespace cashash
