#include "colmap_bridge/pair_list.h"

#include <sstream>
#include <stdexcept>
#include <unordered_set>

#include "cashash/base/pair_id.h"

namespace cashash {
namespace colmap {
namespace {

std::string Trim(const std::string& s) {
  const size_t begin = s.find_first_not_of(" \t\r\n");
  if (begin == std::string::npos) return "";
  const size_t end = s.find_last_not_of(" \t\r\n");
  return s.substr(begin, end - begin + 1);
}

}  // namespace

std::vector<ImagePair> ParsePairList(std::istream& input, const std::string& source_name,
                                     const std::unordered_map<std::string, image_t>& image_ids_by_name) {
  std::vector<ImagePair> pairs;
  std::unordered_set<pair_t> seen;
  std::string line;
  size_t line_number = 0;
  while (std::getline(input, line)) {
    ++line_number;
    line = Trim(line);
    if (line.empty() || line[0] == '#') continue;
    std::istringstream fields(line);
    std::string name1, name2, extra;
    const std::string where = source_name + ":" + std::to_string(line_number);
    if (!(fields >> name1 >> name2) || (fields >> extra)) {
      throw std::runtime_error(where + ": expected 'name1 name2', found '" + line + "'");
    }
    const auto it1 = image_ids_by_name.find(name1);
    if (it1 == image_ids_by_name.end()) throw std::runtime_error(where + ": image '" + name1 + "' is not in table images");
    const auto it2 = image_ids_by_name.find(name2);
    if (it2 == image_ids_by_name.end()) throw std::runtime_error(where + ": image '" + name2 + "' is not in table images");
    if (it1->second == it2->second) throw std::runtime_error(where + ": pair of image '" + name1 + "' with itself");
    if (seen.insert(ImagePairToPairId(it1->second, it2->second)).second) {
      pairs.emplace_back(it1->second, it2->second);
    }
  }
  return pairs;
}

}  // namespace colmap
}  // namespace cashash
