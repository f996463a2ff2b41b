// COLMAP's sequential pairs (SequentialPairGenerator of COLMAP 4.x): name
// order, linear and quadratic overlap, rig frames, loop detection queries
// and the loop pairs kept from a retrieval's answer.
#include "cashash/pipeline/sequential_pairs.h"

#include <set>

#include <gtest/gtest.h>

#include "cashash/base/pair_id.h"
#include "pair_id_sets.h"

namespace cashash {
namespace {

using testing_support::PairIds;

// n images named frame_000..., with ids that do not follow the names.
std::vector<SequenceImage> Sequence(int n) {
  std::vector<SequenceImage> images;
  for (int i = 0; i < n; ++i) {
    SequenceImage image;
    image.image_id = static_cast<image_t>(1000 - 7 * i);
    char name[32];
    std::snprintf(name, sizeof(name), "frame_%03d.jpg", i);
    image.name = name;
    image.camera_id = 1;
    images.push_back(image);
  }
  // Handed over in an order that is neither names nor ids.
  std::swap(images[0], images[n / 2]);
  return images;
}

image_t IdAt(int index) { return static_cast<image_t>(1000 - 7 * index); }

TEST(SequentialPairs, OrderByNameNotById) {
  const std::vector<image_t> order = OrderByName(Sequence(5));
  EXPECT_EQ(order, (std::vector<image_t>{IdAt(0), IdAt(1), IdAt(2), IdAt(3), IdAt(4)}));
  // Byte order, as std::string compares: upper case before lower case, "10" before "9".
  std::vector<SequenceImage> names = {{1, "b.jpg", 1, 0}, {2, "B.jpg", 1, 0}, {3, "img10.jpg", 1, 0},
                                      {4, "img9.jpg", 1, 0}};
  EXPECT_EQ(OrderByName(names), (std::vector<image_t>{2, 1, 3, 4}));
}

TEST(SequentialPairs, LinearOverlapPairsTheNextImages) {
  SequentialPairingOptions options;
  options.overlap = 2;
  options.quadratic_overlap = false;
  const std::vector<ImagePair> pairs = SequentialPairs(Sequence(5), options);
  EXPECT_EQ(PairIds(pairs), PairIds({{IdAt(0), IdAt(1)}, {IdAt(0), IdAt(2)}, {IdAt(1), IdAt(2)}, {IdAt(1), IdAt(3)},
                                     {IdAt(2), IdAt(3)}, {IdAt(2), IdAt(4)}, {IdAt(3), IdAt(4)}}));
  // As COLMAP makes them: (image, later image), by image in name order.
  EXPECT_EQ(pairs.front(), ImagePair(IdAt(0), IdAt(1)));
  EXPECT_EQ(pairs.back(), ImagePair(IdAt(3), IdAt(4)));
}

TEST(SequentialPairs, QuadraticOverlapPairsPowersOfTwoOn) {
  SequentialPairingOptions options;
  options.overlap = 4;  // 1, 2, 4, 8 places on
  const std::vector<ImagePair> pairs = SequentialPairs(Sequence(12), options);
  std::set<pair_t> expected;
  for (int i = 0; i < 12; ++i) {
    for (int step : {1, 2, 4, 8}) {
      if (i + step < 12) expected.insert(ImagePairToPairId(IdAt(i), IdAt(i + step)));
    }
  }
  EXPECT_EQ(PairIds(pairs), expected);
}

TEST(SequentialPairs, DefaultsAreColmaps) {
  const SequentialPairingOptions options;
  EXPECT_EQ(options.overlap, 10);
  EXPECT_TRUE(options.quadratic_overlap);
  EXPECT_TRUE(options.expand_rig_images);
  EXPECT_FALSE(options.loop_detection);
  EXPECT_EQ(options.loop_detection_period, 10);
  EXPECT_EQ(options.loop_detection_num_images, 50);
  EXPECT_EQ(options.loop_detection_min_index_distance, 0);
  EXPECT_EQ(options.Check(), "");
  // 1000 images, overlap 10 quadratic: image i reaches i + 512.
  const std::vector<ImagePair> pairs = SequentialPairs(Sequence(1000), options);
  size_t expected = 0;
  for (int i = 0; i < 1000; ++i) {
    for (int k = 0; k < 10; ++k) expected += i + (1 << k) < 1000;
  }
  EXPECT_EQ(pairs.size(), expected);
}

TEST(SequentialPairs, FewImagesAndHugeOverlap) {
  SequentialPairingOptions options;
  options.overlap = 100;  // quadratic: stops at the end, no shift past 63
  EXPECT_TRUE(SequentialPairs({}, options).empty());
  EXPECT_TRUE(SequentialPairs(Sequence(1), options).empty());
  EXPECT_EQ(SequentialPairs(Sequence(3), options).size(), 3u);  // 0-1, 0-2, 1-2
  options.quadratic_overlap = false;
  EXPECT_EQ(SequentialPairs(Sequence(4), options).size(), 6u);
}

// Two cameras of one rig, three frames: names sort camera by camera.
std::vector<SequenceImage> RigSequence() {
  // a = camera 1, b = camera 2; frame k holds a_k and b_k.
  return {{11, "rig/cam1/1.jpg", 1, 1}, {12, "rig/cam1/2.jpg", 1, 2}, {13, "rig/cam1/3.jpg", 1, 3},
          {21, "rig/cam2/1.jpg", 2, 1}, {22, "rig/cam2/2.jpg", 2, 2}, {23, "rig/cam2/3.jpg", 2, 3}};
}

TEST(SequentialPairs, RigFramesExpandAsColmapDoes) {
  SequentialPairingOptions options;
  options.overlap = 1;
  options.quadratic_overlap = false;
  // Each image with its frame, its next image of the same camera and that
  // image's frame; cam1/3 -> cam2/1 crosses cameras and is no neighbour.
  EXPECT_EQ(PairIds(SequentialPairs(RigSequence(), options)),
            PairIds({{11, 21}, {11, 12}, {11, 22}, {12, 22}, {12, 13}, {12, 23}, {13, 23}, {21, 22}, {21, 12},
                     {22, 23}, {22, 13}}));
  options.expand_rig_images = false;
  EXPECT_EQ(PairIds(SequentialPairs(RigSequence(), options)),
            PairIds({{11, 12}, {12, 13}, {13, 21}, {21, 22}, {22, 23}}));
}

TEST(SequentialPairs, FramesOfOneImageChangeNothing) {
  std::vector<SequenceImage> images = Sequence(20);
  for (size_t i = 0; i < images.size(); ++i) {
    images[i].frame_id = static_cast<uint32_t>(i + 1);
    images[i].camera_id = static_cast<camera_t>(i + 1);  // one camera each, as generate_database makes them
  }
  const SequentialPairingOptions options;
  EXPECT_EQ(PairIds(SequentialPairs(images, options)), PairIds(SequentialPairs(Sequence(20), options)));
}

TEST(SequentialPairs, LoopQueriesAreEveryPeriodthImage) {
  SequentialPairingOptions options;
  options.loop_detection_period = 3;
  EXPECT_EQ(LoopDetectionQueries({5, 6, 7, 8, 9, 10, 11}, options), (std::vector<image_t>{5, 8, 11}));
  EXPECT_EQ(LoopDetectionQueries({5, 6, 7}, options), (std::vector<image_t>{5}));
  EXPECT_TRUE(LoopDetectionQueries({}, options).empty());
}

TEST(SequentialPairs, LoopPairsKeepTheMostSimilarFarEnoughImages) {
  const std::vector<image_t> ordered = {10, 11, 12, 13, 14, 15, 16, 17, 18, 19};
  SequentialPairingOptions options;
  options.loop_detection_num_images = 2;
  // The query itself and repeats are dropped; at most two per query.
  EXPECT_EQ(LoopDetectionPairs(ordered, {10, 15}, {{10, 18, 11, 19}, {11, 16, 17}}, options),
            (std::vector<ImagePair>{{10, 18}, {10, 11}, {15, 11}, {15, 16}}));
  // min_index_distance 3: 10 keeps 18 and 19 (8 and 9 places away), 15 keeps only 11 (4 away).
  options.loop_detection_min_index_distance = 3;
  EXPECT_EQ(LoopDetectionPairs(ordered, {10, 15}, {{10, 18, 11, 19}, {11, 16, 17}}, options),
            (std::vector<ImagePair>{{10, 18}, {10, 19}, {15, 11}}));
  // Enough asked for: num_images plus the 2 (d - 1) images closer than d.
  EXPECT_EQ(LoopDetectionRetrievalCount(options), 2 + 4);
  EXPECT_THROW(LoopDetectionPairs(ordered, {10}, {{99}}, options), std::invalid_argument);
  EXPECT_THROW(LoopDetectionPairs(ordered, {10, 11}, {{12}}, options), std::invalid_argument);
}

TEST(SequentialPairs, AppendNewPairsKeepsEachPairOnce) {
  EXPECT_EQ(AppendNewPairs({{1, 2}, {2, 3}}, {{2, 1}, {1, 5}, {3, 3}, {5, 1}}),
            (std::vector<ImagePair>{{1, 2}, {2, 3}, {1, 5}}));
}

TEST(SequentialPairs, CheckNamesTheOption) {
  SequentialPairingOptions options;
  options.overlap = 0;
  EXPECT_NE(options.Check().find("--SequentialMatching.overlap"), std::string::npos);
  options = SequentialPairingOptions();
  options.loop_detection_period = 0;
  EXPECT_NE(options.Check().find("--SequentialMatching.loop_detection_period"), std::string::npos);
  options = SequentialPairingOptions();
  options.loop_detection_num_images = -1;
  EXPECT_NE(options.Check().find("--SequentialMatching.loop_detection_num_images"), std::string::npos);
  options = SequentialPairingOptions();
  options.loop_detection_min_index_distance = -1;
  EXPECT_NE(options.Check().find("--SequentialMatching.loop_detection_min_index_distance"), std::string::npos);
}

}  // namespace
}  // namespace cashash
