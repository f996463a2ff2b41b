// Parsing of matches_importer's pair lists (--match_type pairs): one
// "name1 name2" per line, '#' comments and blank lines skipped.
#pragma once

#include <istream>
#include <string>
#include <unordered_map>
#include <vector>

#include "cashash/base/types.h"

namespace cashash {
namespace colmap {

// Maps names to image ids; throws std::runtime_error naming the line and
// the name when a line is malformed or names an unknown image. Pairs of an
// image with itself are an error; repeated pairs (in either order) are kept
// once, in their first order.
std::vector<ImagePair> ParsePairList(std::istream& input, const std::string& source_name,
                                     const std::unordered_map<std::string, image_t>& image_ids_by_name);

}  // namespace colmap
}  // namespace cashash
