// libFuzzer target: the input is a whole database file. Everything a
// matching run reads goes through the bridge; a DatabaseError is the
// expected outcome for broken input, anything else (crash, sanitizer report,
// other exception, hang) is a finding. Seeds: small real-schema databases
// written by scripts/sanitize_and_fuzz.sh.
#include <unistd.h>

#include <algorithm>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <string>

#include "colmap_bridge/database.h"
#include "colmap_bridge/database_pipeline_io.h"

namespace {

using cashash::colmap::DatabaseError;
using cashash::colmap::DatabaseFeatureSource;

// One scratch file per process, rewritten for every input.
const std::string& ScratchPath() {
  static const std::string path = [] {
    const char* dir = std::getenv("TMPDIR");
    std::string pattern = std::string(dir != nullptr ? dir : "/tmp") + "/cashash_fuzz_db_XXXXXX";
    const int fd = mkstemp(pattern.data());
    if (fd >= 0) close(fd);
    return pattern;
  }();
  // libFuzzer ends with exit(): leave no scratch file behind.
  static const int registered = std::atexit([] { std::remove(ScratchPath().c_str()); });
  (void)registered;
  return path;
}

void RemoveJournals(const std::string& path) {
  for (const char* suffix : {"-wal", "-shm", "-journal"}) std::remove((path + suffix).c_str());
}

void ReadLikeAMatchingRun(const std::string& path) {
  DatabaseFeatureSource source(path, [](const std::string&) {});
  const size_t num_images = std::min<size_t>(source.images().size(), 8);
  for (size_t i = 0; i < num_images; ++i) {
    const cashash::image_t id = source.images()[i].image_id;
    source.LoadFeatures(id);
    source.CameraOfImage(id);
  }
  source.database().ReadCompletedPairIds();
  for (size_t i = 0; i < num_images && i < 4; ++i) {
    for (size_t j = 0; j < num_images && j < 4; ++j) {
      if (i == j) continue;
      source.database().ReadMatches(source.images()[i].image_id, source.images()[j].image_id);
      source.database().ReadTwoViewGeometry(source.images()[i].image_id,
                                             source.images()[j].image_id);
    }
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string& path = ScratchPath();
  RemoveJournals(path);
  FILE* file = std::fopen(path.c_str(), "wb");
  if (file == nullptr) std::abort();
  if (size > 0 && std::fwrite(data, 1, size, file) != size) std::abort();
  std::fclose(file);
  try {
    ReadLikeAMatchingRun(path);
  } catch (const DatabaseError&) {
    // The expected way to reject a bad database.
  }
  RemoveJournals(path);
  return 0;
}
