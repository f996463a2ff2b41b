#include "colmap_bridge/pair_list.h"

#include <sstream>

#include <gtest/gtest.h>

namespace cashash {
namespace colmap {
namespace {

const std::unordered_map<std::string, image_t> kIds = {{"a.jpg", 1}, {"b.jpg", 2}, {"c.jpg", 3}};

TEST(PairList, SkipsCommentsBlankLinesAndRepeats) {
  std::istringstream in("# header\n\na.jpg b.jpg\n  b.jpg c.jpg  \r\nb.jpg a.jpg\n#x y\n");
  const std::vector<ImagePair> pairs = ParsePairList(in, "pairs.txt", kIds);
  ASSERT_EQ(pairs.size(), 2u);
  EXPECT_EQ(pairs[0], ImagePair(1, 2));
  EXPECT_EQ(pairs[1], ImagePair(2, 3));
}

void ExpectError(const std::string& text, const std::string& expected_part) {
  std::istringstream in(text);
  try {
    ParsePairList(in, "pairs.txt", kIds);
    FAIL() << "no error for: " << text;
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find(expected_part), std::string::npos) << e.what();
  }
}

TEST(PairList, ErrorsNameLineAndImage) {
  ExpectError("a.jpg b.jpg\na.jpg missing.jpg\n", "pairs.txt:2: image 'missing.jpg' is not in table images");
  ExpectError("a.jpg\n", "pairs.txt:1: expected 'name1 name2'");
  ExpectError("a.jpg b.jpg c.jpg\n", "pairs.txt:1: expected");
  ExpectError("c.jpg c.jpg\n", "with itself");
}

}  // namespace
}  // namespace colmap
}  // namespace cashash
