// Bad and damaged databases, and faults while writing: each case must end in
// one DatabaseError naming what is wrong and where (or a warning where COLMAP
// would go on), never a crash, a hang or a silently wrong result. The
// databases are built here with raw SQLite in COLMAP 3.8's (or 4.x's) layout,
// so no COLMAP is needed. docs/RELIABILITY.md lists the cases.
// Over 600 lines because it is one suite of damaged-database cases that share
// the raw-SQLite builders defined here (RawDb, CreateSchema, AddImage).
#include <fcntl.h>
#include <signal.h>
#include <sqlite3.h>
#include <sys/file.h>
#include <sys/resource.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <limits>
#include <random>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "colmap_bridge/api/matching_api.h"
#include "colmap_bridge/blob_codec.h"
#include "colmap_bridge/database.h"
#include "colmap_bridge/database_pipeline_io.h"
#include "colmap_bridge/database_writer_lock.h"

namespace cashash {
namespace colmap {
namespace {

namespace fs = std::filesystem;

class TempDir {
 public:
  TempDir() {
    std::string pattern = (fs::temp_directory_path() / "cashash_reliability_XXXXXX").string();
    path_ = mkdtemp(pattern.data());
  }
  ~TempDir() {
    std::error_code ignored;
    fs::remove_all(path_, ignored);
  }
  std::string File(const std::string& name) const { return path_ + "/" + name; }

 private:
  std::string path_;
};

// Raw SQLite access, independent of the code under test.
class RawDb {
 public:
  explicit RawDb(const std::string& path) {
    if (sqlite3_open(path.c_str(), &db_) != SQLITE_OK) throw std::runtime_error("open " + path);
  }
  ~RawDb() { sqlite3_close(db_); }
  void Exec(const std::string& sql) {
    char* message = nullptr;
    if (sqlite3_exec(db_, sql.c_str(), nullptr, nullptr, &message) != SQLITE_OK) {
      const std::string text = message ? message : "";
      sqlite3_free(message);
      throw std::runtime_error(sql + ": " + text);
    }
  }
  // Runs `sql` with one blob bound to its ?1 (nullptr binds NULL).
  void ExecWithBlob(const std::string& sql, const void* data, size_t num_bytes) {
    sqlite3_stmt* stmt = nullptr;
    if (sqlite3_prepare_v2(db_, sql.c_str(), -1, &stmt, nullptr) != SQLITE_OK) {
      throw std::runtime_error(sql + ": " + sqlite3_errmsg(db_));
    }
    if (data != nullptr) {
      sqlite3_bind_blob(stmt, 1, data, static_cast<int>(num_bytes), SQLITE_TRANSIENT);
    }
    const int rc = sqlite3_step(stmt);
    sqlite3_finalize(stmt);
    if (rc != SQLITE_DONE) throw std::runtime_error(sql + ": " + sqlite3_errmsg(db_));
  }
  std::string QueryText(const std::string& sql) {
    sqlite3_stmt* stmt = nullptr;
    sqlite3_prepare_v2(db_, sql.c_str(), -1, &stmt, nullptr);
    std::string text;
    if (sqlite3_step(stmt) == SQLITE_ROW && sqlite3_column_text(stmt, 0) != nullptr) {
      text = reinterpret_cast<const char*>(sqlite3_column_text(stmt, 0));
    }
    sqlite3_finalize(stmt);
    return text;
  }

 private:
  sqlite3* db_ = nullptr;
};

constexpr int kWidth = 640;
constexpr int kHeight = 480;

// COLMAP 3.8's tables (without the UNIQUE constraint on names when asked, as
// a hand-made database may be), or 4.x's descriptors with a type column.
void CreateSchema(RawDb& raw, bool unique_names = true, bool typed_descriptors = false) {
  raw.Exec("CREATE TABLE cameras(camera_id INTEGER PRIMARY KEY, model INTEGER, width INTEGER, "
           "height INTEGER, params BLOB, prior_focal_length INTEGER)");
  raw.Exec(std::string("CREATE TABLE images(image_id INTEGER PRIMARY KEY, name TEXT") +
           (unique_names ? " UNIQUE" : "") + ", camera_id INTEGER)");
  raw.Exec("CREATE TABLE keypoints(image_id INTEGER PRIMARY KEY, rows INTEGER, cols INTEGER, "
           "data BLOB)");
  raw.Exec(std::string("CREATE TABLE descriptors(image_id INTEGER PRIMARY KEY, ") +
           (typed_descriptors ? "type INTEGER, " : "") + "rows INTEGER, cols INTEGER, data BLOB)");
  raw.Exec("CREATE TABLE matches(pair_id INTEGER PRIMARY KEY, rows INTEGER, cols INTEGER, "
           "data BLOB)");
  raw.Exec("CREATE TABLE two_view_geometries(pair_id INTEGER PRIMARY KEY, rows INTEGER, "
           "cols INTEGER, data BLOB, config INTEGER, F BLOB, E BLOB, H BLOB, qvec BLOB, "
           "tvec BLOB)");
  const double params[4] = {500.0, kWidth / 2.0, kHeight / 2.0, 0.0};
  raw.ExecWithBlob("INSERT INTO cameras VALUES (1, 2, " + std::to_string(kWidth) + ", " +
                       std::to_string(kHeight) + ", ?1, 0)",
                   params, sizeof(params));
}

std::vector<float> Keypoints6(int rows, uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> x(1.0f, kWidth - 1.0f), y(1.0f, kHeight - 1.0f);
  std::vector<float> values;
  for (int i = 0; i < rows; ++i) {
    values.insert(values.end(), {x(rng), y(rng), 2.0f, 0.0f, 0.0f, 2.0f});
  }
  return values;
}

std::vector<uint8_t> Descriptors(int rows, uint32_t seed) {
  std::mt19937 rng(seed);
  std::vector<uint8_t> values(static_cast<size_t>(rows) * 128);
  for (uint8_t& v : values) v = static_cast<uint8_t>(rng() % 60);
  return values;
}

// An image with `rows` good keypoints and descriptors.
void AddImage(RawDb& raw, int image_id, const std::string& name, int rows) {
  raw.Exec("INSERT INTO images VALUES (" + std::to_string(image_id) + ", '" + name + "', 1)");
  const std::vector<float> kp = Keypoints6(rows, image_id);
  raw.ExecWithBlob("INSERT INTO keypoints VALUES (" + std::to_string(image_id) + ", " +
                       std::to_string(rows) + ", 6, ?1)",
                   kp.data(), kp.size() * sizeof(float));
  const std::vector<uint8_t> d = Descriptors(rows, image_id);
  raw.ExecWithBlob("INSERT INTO descriptors VALUES (" + std::to_string(image_id) + ", " +
                       std::to_string(rows) + ", 128, ?1)",
                   d.data(), d.size());
}

// A good database of `num_images` images with `rows` features each.
std::string MakeDatabase(const TempDir& dir, const std::string& name, int num_images, int rows,
                         bool unique_names = true) {
  const std::string path = dir.File(name);
  RawDb raw(path);
  CreateSchema(raw, unique_names);
  raw.Exec("BEGIN");
  for (int i = 1; i <= num_images; ++i) AddImage(raw, i, "im" + std::to_string(i) + ".jpg", rows);
  raw.Exec("COMMIT");
  return path;
}

template <typename F>
std::string ErrorOf(F f) {
  try {
    f();
  } catch (const DatabaseError& error) {
    return error.what();
  }
  return "";
}

bool Contains(const std::string& text, const std::string& part) {
  return text.find(part) != std::string::npos;
}

// Loads every image through the pipeline's source: what a matching run does.
void LoadEverything(const std::string& path) {
  DatabaseFeatureSource source(path);
  for (const Image& image : source.images()) source.LoadFeatures(image.image_id);
}

std::string IntegrityOf(const std::string& path) {
  RawDb raw(path);
  return raw.QueryText("PRAGMA integrity_check");
}

PairResult ResultWithMatches(image_t id1, image_t id2, size_t count) {
  PairResult result;
  result.pair = {id1, id2};
  for (size_t i = 0; i < count; ++i) {
    result.matches.push_back({static_cast<point2D_t>(i), static_cast<point2D_t>(i)});
  }
  return result;
}

size_t CountRows(const std::string& path, const std::string& table) {
  RawDb raw(path);
  return std::stoul(raw.QueryText("SELECT COUNT(*) FROM " + table));
}

// --- Files that are not (whole) SQLite databases -----------------------------

TEST(ReliabilityFileTest, RandomBytesAreNotADatabase) {
  TempDir dir;
  const std::string path = dir.File("random.db");
  std::mt19937 rng(3);
  std::string bytes(8192, '\0');
  for (char& c : bytes) c = static_cast<char>(rng());
  std::ofstream(path, std::ios::binary) << bytes;
  EXPECT_EQ(ErrorOf([&] { LoadEverything(path); }), "not a SQLite database: " + path);
}

TEST(ReliabilityFileTest, EmptyFileHasNoTables) {
  // SQLite treats a 0-byte file as an empty database.
  TempDir dir;
  const std::string path = dir.File("empty.db");
  std::ofstream(path).close();
  const std::string error = ErrorOf([&] { LoadEverything(path); });
  EXPECT_TRUE(Contains(error, "has no table 'cameras'")) << error;
}

// Cutting the file at any page boundary or in the middle of a page: an error
// that names the file, never a crash.
TEST(ReliabilityFileTest, TruncatedDatabase) {
  TempDir dir;
  const std::string good = MakeDatabase(dir, "good.db", 6, 300);
  const auto size = fs::file_size(good);
  ASSERT_GT(size, 40000u);
  for (const double fraction : {0.02, 0.1, 0.35, 0.5, 0.8, 0.97}) {
    const std::string path = dir.File("cut.db");
    fs::copy_file(good, path, fs::copy_options::overwrite_existing);
    fs::resize_file(path, static_cast<uintmax_t>(size * fraction));
    const std::string error = ErrorOf([&] { LoadEverything(path); });
    EXPECT_TRUE(Contains(error, path)) << fraction << ": " << error;
    EXPECT_TRUE(Contains(error, "damaged") || Contains(error, "malformed") ||
                Contains(error, "not a SQLite database"))
        << fraction << ": " << error;
  }
}

// Garbage written over the table pages (the header page stays intact).
TEST(ReliabilityFileTest, CorruptedPages) {
  TempDir dir;
  const std::string good = MakeDatabase(dir, "good.db", 6, 300);
  const auto size = fs::file_size(good);
  std::mt19937 rng(11);
  int errors = 0;
  for (int trial = 0; trial < 8; ++trial) {
    const std::string path = dir.File("corrupt.db");
    fs::copy_file(good, path, fs::copy_options::overwrite_existing);
    {
      std::fstream file(path, std::ios::in | std::ios::out | std::ios::binary);
      // The schema's pages come first; garbage over pages 2 .. 5 breaks the
      // b-trees of the tables themselves.
      file.seekp(4096 + static_cast<std::streamoff>(rng() % (4 * 4096)));
      for (int i = 0; i < 2048; ++i) file.put(static_cast<char>(rng()));
    }
    ASSERT_EQ(fs::file_size(path), size);
    const std::string error = ErrorOf([&] { LoadEverything(path); });
    // Some garbage lands in blob bytes only: then the data read are wrong
    // but well-formed, as with any flipped bit. Errors must name the file.
    if (!error.empty()) {
      ++errors;
      EXPECT_TRUE(Contains(error, path) || Contains(error, "image")) << error;
    }
  }
  EXPECT_GT(errors, 0);
}

// --- Tables and columns ------------------------------------------------------

TEST(ReliabilityTableTest, MissingTableIsNamed) {
  TempDir dir;
  const std::string path = MakeDatabase(dir, "db.db", 2, 10);
  {
    RawDb raw(path);
    raw.Exec("DROP TABLE two_view_geometries");
  }
  const std::string error = ErrorOf([&] { DatabaseResultSink sink(path, true); });
  EXPECT_TRUE(Contains(error, "has no table 'two_view_geometries'")) << error;
}

// SQLite is dynamically typed: a column may hold text where COLMAP writes
// integers or blobs.
TEST(ReliabilityTableTest, WrongColumnTypes) {
  TempDir dir;
  const std::string path = MakeDatabase(dir, "db.db", 5, 20);
  {
    RawDb raw(path);
    raw.Exec("UPDATE keypoints SET rows = 'twenty' WHERE image_id = 1");
    raw.Exec("UPDATE descriptors SET data = 'not a blob' WHERE image_id = 2");
    raw.Exec("UPDATE keypoints SET cols = 'six' WHERE image_id = 3");
    raw.Exec("UPDATE descriptors SET data = NULL WHERE image_id = 4");
    // Text that reads as the right integer is what SQLite itself accepts.
    raw.Exec("UPDATE keypoints SET rows = '20' WHERE image_id = 5");
  }
  Database db(path, /*read_only=*/true);
  EXPECT_TRUE(Contains(ErrorOf([&] { db.ReadKeypoints(1); }),
                       "keypoints of image 1 (im1.jpg): blob size 480 does not match rows x "
                       "cols = 0 x 6"));
  EXPECT_TRUE(Contains(ErrorOf([&] { db.ReadDescriptors(2); }),
                       "descriptors of image 2 (im2.jpg): blob size 10 does not match"));
  EXPECT_TRUE(Contains(ErrorOf([&] { db.ReadKeypoints(3); }),
                       "keypoints of image 3 (im3.jpg): expected float32 keypoints with 2, 4 "
                       "or 6 columns, found 0 columns"));
  EXPECT_TRUE(Contains(ErrorOf([&] { db.ReadDescriptors(4); }),
                       "descriptors of image 4 (im4.jpg): blob size 0 does not match rows x "
                       "cols = 20 x 128"));
  EXPECT_EQ(db.ReadKeypoints(5).size(), 20u);
}

// rows x cols x element size wrapping around 2^64 to the blob's size must not
// pass the size check (it would size a huge allocation).
TEST(ReliabilityTableTest, ShapeOverflowIsRejected) {
  const std::string error = ErrorOf([] {
    MatrixBlob blob;
    blob.rows = int64_t{1} << 62;
    blob.cols = 4;  // 2^62 x 4 x 4 bytes = 2^66, 0 modulo 2^64
    DecodeKeypoints(blob, "keypoints of image 9 (x.jpg)");
  });
  EXPECT_TRUE(Contains(error, "keypoints of image 9 (x.jpg): blob size 0 does not match rows x "
                              "cols = 4611686018427387904 x 4"))
      << error;
  const std::string descriptor_error = ErrorOf([] {
    MatrixBlob blob;
    blob.rows = int64_t{1} << 57;  // x 128 = 2^64
    blob.cols = 128;
    DecodeSiftDescriptors(blob, "descriptors of image 9 (x.jpg)");
  });
  EXPECT_TRUE(Contains(descriptor_error, "more than 2^64")) << descriptor_error;
  const std::string match_error = ErrorOf([] {
    MatrixBlob blob;
    blob.rows = int64_t{1} << 61;  // x 2 x 4 = 2^64
    blob.cols = 2;
    uint32_t one_match[2] = {0, 0};
    blob.data = one_match;
    blob.num_bytes = 0;
    DecodeMatches(blob, false, "matches of pair 5");
  });
  EXPECT_TRUE(Contains(match_error, "matches of pair 5: blob size 0")) << match_error;
}

// --- Descriptors that are not SIFT --------------------------------------------

TEST(ReliabilityDescriptorTest, FloatOrOtherWidthIsRejected) {
  TempDir dir;
  const std::string path = MakeDatabase(dir, "db.db", 3, 8);
  {
    RawDb raw(path);
    const std::vector<float> floats(8 * 128, 0.1f);
    raw.ExecWithBlob("UPDATE descriptors SET data = ?1 WHERE image_id = 1", floats.data(),
                     floats.size() * sizeof(float));
    const std::vector<uint8_t> wide(8 * 256);
    raw.ExecWithBlob("UPDATE descriptors SET cols = 256, data = ?1 WHERE image_id = 2",
                     wide.data(), wide.size());
  }
  const std::string float_error = ErrorOf([&] { LoadEverything(path); });
  EXPECT_TRUE(Contains(float_error, "descriptors of image 1 (im1.jpg)")) << float_error;
  EXPECT_TRUE(Contains(float_error, "float32")) << float_error;
  Database db(path, true);
  EXPECT_EQ(ErrorOf([&] { db.ReadDescriptors(2); }),
            "descriptors of image 2 (im2.jpg): expected uint8 x 128 SIFT descriptors, found 256 "
            "columns");
}

// COLMAP 4's ALIKED features: float32 x 128 stored as 512 bytes per row.
TEST(ReliabilityDescriptorTest, AlikedIsNotSupported) {
  TempDir dir;
  const std::string path = dir.File("aliked.db");
  {
    RawDb raw(path);
    CreateSchema(raw, true, /*typed_descriptors=*/true);
    raw.Exec("INSERT INTO images VALUES (1, 'a.jpg', 1)");
    const std::vector<float> kp = Keypoints6(4, 1);
    raw.ExecWithBlob("INSERT INTO keypoints VALUES (1, 4, 6, ?1)", kp.data(),
                     kp.size() * sizeof(float));
    const std::vector<uint8_t> aliked(4 * 512);
    raw.ExecWithBlob("INSERT INTO descriptors VALUES (1, 2, 4, 512, ?1)", aliked.data(),
                     aliked.size());
  }
  EXPECT_EQ(ErrorOf([&] { LoadEverything(path); }),
            "descriptors of image 1 (a.jpg): descriptor type ALIKED_N32 (2) is not supported; "
            "extract SIFT features");
}

// --- Keypoints ---------------------------------------------------------------

TEST(ReliabilityKeypointTest, NonFiniteValuesAreRejected) {
  TempDir dir;
  const std::string path = MakeDatabase(dir, "db.db", 3, 10);
  {
    RawDb raw(path);
    std::vector<float> kp = Keypoints6(10, 2);
    kp[6 * 7 + 1] = std::numeric_limits<float>::quiet_NaN();
    raw.ExecWithBlob("UPDATE keypoints SET data = ?1 WHERE image_id = 2", kp.data(),
                     kp.size() * sizeof(float));
    kp = Keypoints6(10, 3);
    kp[6 * 2 + 3] = std::numeric_limits<float>::infinity();
    raw.ExecWithBlob("UPDATE keypoints SET data = ?1 WHERE image_id = 3", kp.data(),
                     kp.size() * sizeof(float));
  }
  EXPECT_EQ(ErrorOf([&] { LoadEverything(path); }),
            "keypoints of image 2 (im2.jpg): row 7 holds a non-finite value (nan) in column 1");
  Database db(path, true);
  EXPECT_EQ(ErrorOf([&] { db.ReadKeypoints(3); }),
            "keypoints of image 3 (im3.jpg): row 2 holds a non-finite value (inf) in column 3");
}

// COLMAP matches keypoints wherever they are; we do too, with one warning
// per image.
TEST(ReliabilityKeypointTest, OutsideTheImageWarnsOnce) {
  TempDir dir;
  const std::string path = MakeDatabase(dir, "db.db", 2, 10);
  {
    RawDb raw(path);
    std::vector<float> kp = Keypoints6(10, 1);
    kp[6 * 4] = -50.0f;
    kp[6 * 8 + 1] = kHeight + 300.0f;
    raw.ExecWithBlob("UPDATE keypoints SET data = ?1 WHERE image_id = 1", kp.data(),
                     kp.size() * sizeof(float));
  }
  std::vector<std::string> warnings;
  DatabaseFeatureSource source(path, [&](const std::string& text) { warnings.push_back(text); });
  EXPECT_EQ(source.LoadFeatures(1).keypoints.size(), 10u);
  EXPECT_EQ(source.LoadFeatures(1).keypoints.size(), 10u);
  EXPECT_EQ(source.LoadFeatures(2).keypoints.size(), 10u);
  // Once per image; the warning names the image, how many keypoints and
  // the first row at fault.
  ASSERT_EQ(warnings.size(), 1u);
  EXPECT_TRUE(Contains(warnings[0], "im1.jpg")) << warnings[0];
  EXPECT_TRUE(Contains(warnings[0], "2 of 10")) << warnings[0];
  EXPECT_TRUE(Contains(warnings[0], "row 4")) << warnings[0];
}

// A run's warnings about the data (keypoints outside the image, a camera
// model unknown to cashash) reach its warning callback, as the others do:
// Python turns them into RuntimeWarnings, the command line prints them.
TEST(ReliabilityKeypointTest, DataWarningsReachTheRunsCallback) {
  TempDir dir;
  const std::string path = MakeDatabase(dir, "db.db", 2, 10);
  {
    RawDb raw(path);
    std::vector<float> kp = Keypoints6(10, 1);
    kp[6 * 4] = -50.0f;
    raw.ExecWithBlob("UPDATE keypoints SET data = ?1 WHERE image_id = 1", kp.data(),
                     kp.size() * sizeof(float));
    raw.Exec("UPDATE cameras SET model = 99");
  }
  MatcherCommandOptions options;
  options.use_gpu = false;
  options.cashash.matcher = MatcherType::kBruteForce;
  std::vector<std::string> warnings;
  MatchingCallbacks callbacks;
  callbacks.warning = [&](const std::string& text) { warnings.push_back(text); };
  MatchExhaustive(path, options, callbacks);
  size_t outside = 0, unknown_model = 0;
  for (const std::string& text : warnings) {
    outside += Contains(text, "keypoints lie outside the 640 x 480 image") ? 1 : 0;
    unknown_model += Contains(text, "has model id 99, unknown to cashash") ? 1 : 0;
  }
  EXPECT_EQ(outside, 1u);
  EXPECT_EQ(unknown_model, 1u);
}

// --- Images ------------------------------------------------------------------

TEST(ReliabilityImageTest, DuplicateNamesAreRejected) {
  TempDir dir;
  const std::string path = MakeDatabase(dir, "db.db", 3, 5, /*unique_names=*/false);
  {
    RawDb raw(path);
    raw.Exec("UPDATE images SET name = 'im1.jpg' WHERE image_id = 3");
  }
  EXPECT_EQ(ErrorOf([&] { DatabaseFeatureSource source(path); }),
            "table images: images 1 and 3 have the same name 'im1.jpg'");
}

TEST(ReliabilityImageTest, ImagesWithoutFeatures) {
  TempDir dir;
  const std::string path = MakeDatabase(dir, "db.db", 2, 5);
  {
    RawDb raw(path);
    raw.Exec("INSERT INTO images VALUES (3, 'none.jpg', 1)");  // no feature rows at all
    raw.Exec("INSERT INTO images VALUES (4, 'half.jpg', 1)");  // descriptors only
    const std::vector<uint8_t> d = Descriptors(5, 4);
    raw.ExecWithBlob("INSERT INTO descriptors VALUES (4, 5, 128, ?1)", d.data(), d.size());
    raw.Exec("INSERT INTO keypoints VALUES (5, 0, 6, NULL)");  // no image row
  }
  DatabaseFeatureSource source(path);
  const ImageFeatures none = source.LoadFeatures(3);
  EXPECT_EQ(none.keypoints.size(), 0u);
  EXPECT_EQ(none.descriptors.rows(), 0u);
  EXPECT_EQ(ErrorOf([&] { source.LoadFeatures(4); }),
            "image 4 (half.jpg): table keypoints has 0 rows but table descriptors has 5");
}

TEST(ReliabilityImageTest, UnknownCameraIsNamed) {
  TempDir dir;
  const std::string path = MakeDatabase(dir, "db.db", 2, 5);
  {
    RawDb raw(path);
    raw.Exec("UPDATE images SET camera_id = 7 WHERE image_id = 2");
  }
  EXPECT_EQ(ErrorOf([&] { DatabaseFeatureSource source(path); }),
            "table images: image 2 (im2.jpg) refers to camera 7, which is not in table cameras");
}

TEST(ReliabilityImageTest, CameraParamsMustFitTheModel) {
  TempDir dir;
  const std::string path = MakeDatabase(dir, "db.db", 2, 5);
  {
    RawDb raw(path);
    const double params[3] = {500.0, 320.0, 240.0};  // SIMPLE_RADIAL has 4
    raw.ExecWithBlob("UPDATE cameras SET params = ?1", params, sizeof(params));
  }
  EXPECT_EQ(ErrorOf([&] { DatabaseFeatureSource source(path); }),
            "table cameras: camera 1 (SIMPLE_RADIAL) has 3 params, the model has 4");
  {
    RawDb raw(path);
    const double params[4] = {500.0, std::nan(""), 240.0, 0.0};
    raw.ExecWithBlob("UPDATE cameras SET params = ?1", params, sizeof(params));
  }
  EXPECT_EQ(ErrorOf([&] { DatabaseFeatureSource source(path); }),
            "table cameras: camera 1: param 1 is not finite");
}

// --- Faults while writing ----------------------------------------------------

// Another writer keeps the lock past the busy timeout: a clear error naming
// the file, nothing half-written, and the next chunk goes through once the
// lock is free.
TEST(ReliabilityFaultTest, LockedDatabaseTimesOut) {
  TempDir dir;
  const std::string path = MakeDatabase(dir, "db.db", 3, 5);
  DatabaseResultSink::Options options;
  options.busy_timeout_ms = 300;
  DatabaseResultSink sink(path, options);
  {
    RawDb other(path);
    other.Exec("BEGIN IMMEDIATE");
    const auto start = std::chrono::steady_clock::now();
    const std::string error = ErrorOf([&] { sink.WriteChunk({ResultWithMatches(1, 2, 4)}); });
    const double waited =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    EXPECT_TRUE(Contains(error, "database is locked")) << error;
    EXPECT_TRUE(Contains(error, path)) << error;
    EXPECT_TRUE(Contains(error, "busy timeout")) << error;
    EXPECT_GE(waited, 0.25);
    EXPECT_LT(waited, 10.0);
    other.Exec("ROLLBACK");
  }
  EXPECT_EQ(CountRows(path, "matches"), 0u);
  sink.WriteChunk({ResultWithMatches(1, 2, 4), ResultWithMatches(1, 3, 2)});
  sink.Flush();
  EXPECT_EQ(CountRows(path, "matches"), 2u);
  EXPECT_EQ(IntegrityOf(path), "ok");
}

// The file may not grow (RLIMIT_FSIZE stands in for a full disk): the chunk
// fails as a whole, committed chunks stay, and the file stays valid.
TEST(ReliabilityFaultTest, DiskFullWhileWriting) {
  TempDir dir;
  const std::string path = MakeDatabase(dir, "db.db", 4, 5);
  {
    DatabaseResultSink sink(path, true);
    sink.WriteChunk({ResultWithMatches(1, 2, 10)});
  }
  // Checkpoint the WAL, if any, so that the limit applies to fresh writes.
  { RawDb raw(path); raw.Exec("PRAGMA wal_checkpoint(TRUNCATE)"); }
  const auto limit = static_cast<rlim_t>(fs::file_size(path) + 8192);

  struct rlimit old_limit;
  getrlimit(RLIMIT_FSIZE, &old_limit);
  // Past the limit write() fails with EFBIG instead of raising SIGXFSZ.
  struct sigaction ignore{}, old_action{};
  ignore.sa_handler = SIG_IGN;
  sigaction(SIGXFSZ, &ignore, &old_action);
  std::string error;
  {
    DatabaseResultSink sink(path, true);
    struct rlimit small = {limit, old_limit.rlim_max};
    ASSERT_EQ(setrlimit(RLIMIT_FSIZE, &small), 0);
    // 40k matches: 320 kB, far past the limit; written to the file at the
    // latest when the transaction commits.
    error = ErrorOf([&] {
      sink.WriteChunk({ResultWithMatches(1, 3, 40000)});
      sink.Flush();
    });
    setrlimit(RLIMIT_FSIZE, &old_limit);
  }
  sigaction(SIGXFSZ, &old_action, nullptr);
  EXPECT_TRUE(Contains(error, path)) << error;
  EXPECT_TRUE(Contains(error, "disk I/O error") || Contains(error, "full")) << error;
  EXPECT_TRUE(Contains(error, "disk full")) << error;
  EXPECT_EQ(IntegrityOf(path), "ok");
  EXPECT_EQ(CountRows(path, "matches"), 1u);
  Database db(path, true);
  EXPECT_EQ(db.ReadMatches(1, 2).size(), 10u);
  EXPECT_EQ(db.ReadMatches(1, 3).size(), 0u);
}

// Two writers on one file: the second is refused while the first holds it;
// writers of one process nest; the lock goes with the last of them.
TEST(ReliabilityFaultTest, OneWriterPerDatabase) {
  TempDir dir;
  const std::string path = MakeDatabase(dir, "db.db", 2, 5);
  // Another process's lock is another open file description: flock on a
  // fresh descriptor here sees exactly what a second process would.
  auto locked_elsewhere = [&]() {
    const int fd = open(path.c_str(), O_RDONLY);
    const bool busy = flock(fd, LOCK_EX | LOCK_NB) != 0;
    if (!busy) flock(fd, LOCK_UN);
    close(fd);  // this process holds no SQLite connection on the file here
    return busy;
  };
  {
    const int other = open(path.c_str(), O_RDONLY);
    ASSERT_EQ(flock(other, LOCK_EX | LOCK_NB), 0);
    const std::string error = ErrorOf([&] { DatabaseResultSink sink(path, true); });
    EXPECT_EQ(error, "database " + path +
                         " is being matched by another cashash process; wait for it to finish "
                         "(or stop it, then run again to resume)");
    flock(other, LOCK_UN);
    close(other);
  }
  {
    DatabaseWriterLock first(path);
    {
      DatabaseWriterLock nested(path);
      EXPECT_TRUE(locked_elsewhere());
    }
    EXPECT_TRUE(locked_elsewhere());
  }
  EXPECT_FALSE(locked_elsewhere());
}

}  // namespace
}  // namespace colmap
}  // namespace cashash
