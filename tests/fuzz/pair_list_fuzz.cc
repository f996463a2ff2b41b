// libFuzzer target: matches_importer's pair-list parser. It must return
// pairs of known, distinct images, each pair once, or throw a
// std::runtime_error naming the line.
#include <cstdint>
#include <sstream>
#include <stdexcept>
#include <string>
#include <unordered_map>
#include <unordered_set>

#include "cashash/base/pair_id.h"
#include "colmap_bridge/pair_list.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  static const std::unordered_map<std::string, cashash::image_t> kIds = {
      {"a.jpg", 1}, {"b.jpg", 2}, {"c.png", 3}, {"dir/d.JPG", 7}, {"#e.jpg", 9}};
  std::istringstream input(std::string(reinterpret_cast<const char*>(data), size));
  try {
    const std::vector<cashash::ImagePair> pairs =
        cashash::colmap::ParsePairList(input, "pairs.txt", kIds);
    std::unordered_set<cashash::pair_t> seen;
    for (const cashash::ImagePair& pair : pairs) {
      if (pair.first == pair.second) __builtin_trap();
      if (!seen.insert(cashash::ImagePairToPairId(pair.first, pair.second)).second) {
        __builtin_trap();
      }
      bool first_known = false, second_known = false;
      for (const auto& entry : kIds) {
        first_known |= entry.second == pair.first;
        second_known |= entry.second == pair.second;
      }
      if (!first_known || !second_known) __builtin_trap();
    }
  } catch (const std::runtime_error& error) {
    if (std::string(error.what()).rfind("pairs.txt:", 0) != 0) __builtin_trap();
  }
  return 0;
}
