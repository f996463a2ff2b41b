// How long this process has run, for the summary: the pipeline's own time
// leaves out what a user also waits for (opening the database, starting the
// GPU, sizing the hash tables).
#pragma once

namespace cashash {
namespace colmap {

// Seconds since this process started (since static initialisation, a few
// milliseconds after exec).
double SecondsSinceProcessStart();

}  // namespace colmap
}  // namespace cashash
