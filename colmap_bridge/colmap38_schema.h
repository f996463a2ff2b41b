// An empty COLMAP database with the tables of COLMAP 3.8, for databases that
// cashash writes from scratch (generate_database). Every COLMAP from 3.8 on
// opens it (later versions upgrade the schema in place).
#pragma once

#include <string>

namespace cashash {
namespace colmap {

// COLMAP 3.8 numbers its schema 3800 in PRAGMA user_version.
constexpr int kColmap38UserVersion = 3800;

// Creates `path` with the cameras, images, keypoints, descriptors, matches and
// two_view_geometries tables of COLMAP 3.8 and user_version 3800. Throws
// DatabaseError when the file exists already or cannot be created. The
// journal stays the rollback journal, which costs nothing for bulk appends;
// SetWalJournal switches to COLMAP's WAL afterwards.
void CreateColmap38Database(const std::string& path);

// Sets the persistent WAL journal mode that COLMAP uses for its databases.
void SetWalJournal(const std::string& path);

}  // namespace colmap
}  // namespace cashash
