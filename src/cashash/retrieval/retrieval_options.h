// Options of image retrieval from the cascade's own hash codes (no
// vocabulary tree): which images are similar enough to be worth matching.
// The names follow COLMAP's VocabTreeMatching.* where they mean the same;
// docs/retrieval.md describes the method.
#pragma once

#include <cstdint>
#include <string>

namespace cashash {

struct RetrievalOptions {
  // Each image is paired with its num_images most similar images
  // (VocabTreeMatching.num_images, COLMAP's default 100).
  int num_images = 100;
  // Visual words a query feature looks up in each table: its own cell and
  // the num_nearest_neighbors - 1 cells nearest to it (across its least
  // certain hash bits), as COLMAP assigns a feature to its
  // num_nearest_neighbors nearest words. Only the query side is spread, so
  // the index does not grow. Default 1, not COLMAP's 5: with several
  // tables of fine words, more cells found no more overlapping pairs on
  // the generated street (docs/retrieval.md) and cost 5x the query
  // memory.
  int num_nearest_neighbors = 1;
  // Features of an image that are indexed, largest scales first (COLMAP's
  // VocabTreeMatching.max_num_features; -1 = all).
  int max_num_features = -1;
  // Hash tables per feature: each gives every feature one word of
  // bits_per_word bits, from projections of its own (drawn from
  // random_seed, as the cascade's are). More tables, more chances that two
  // views of one point share a word.
  int num_tables = 4;
  // Bits of one word; 0 = chosen from the features per image
  // (RetrievalBitsPerWord): about 1,024 cells per feature of an image, so
  // a word occurs in few images and a query touches few postings.
  int bits_per_word = 0;
  // Words held by more than this share of the images, and by more than
  // kMinStopWordImages, are stop words and left out
  // (Retrieval.max_word_image_fraction). Random-hyperplane cells are
  // uneven: the fullest hold features of many images, say little about
  // overlap (low idf) and are most of the postings a query reads. On a
  // 500-image synthetic street of 4,096 features, 0.05 cut the postings
  // read 2.6x and retrieved as many neighbours (docs/retrieval.md).
  double max_word_image_fraction = 0.05;
  static constexpr int kMinStopWordImages = 50;
  uint64_t random_seed = 0;
  int num_threads = -1;  // -1: every core

  static constexpr int kMaxNearestNeighbors = 8;
  static constexpr int kMaxTables = 16;
  static constexpr int kMinBitsPerWord = 8;
  static constexpr int kMaxBitsPerWord = 24;

  // "" or a message naming the option (--VocabTreeMatching.* or
  // --Retrieval.* as on the command line).
  std::string Check() const;
};

// bits_per_word for images of `features_per_image` features (the median
// image of the run, after max_num_features): log2 of it plus 10, within
// [kMinBitsPerWord, kMaxBitsPerWord]. A word then holds about 1/1,024 of
// an image's features. Finer words lose more true pairs of features to
// the cell borders but far more chance pairs: on the 1,000 x 1,024
// generated street, +8 bits retrieved 99.78 % of the verified pairs and
// read 33 M postings, +10 99.98 % and 16 M, +12 100 % and 9 M; on
// herzjesu-P25 +8 and +10 retrieve the same pairs. +10 keeps the
// vocabulary (num_tables x 2^bits words, arrays of that size while
// indexing) at 16 M words for 4,096 features.
int RetrievalBitsPerWord(const RetrievalOptions& options, size_t features_per_image);

}  // namespace cashash
