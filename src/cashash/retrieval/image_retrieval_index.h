// An inverted file over the visual words of a set of images (visual_words.h)
// that finds, for each image, the images most likely to overlap it: tf-idf
// bag-of-words retrieval (Sivic and Zisserman 2003) with the vocabulary
// taken from the cascade's hash codes instead of a trained tree. Knows no
// database and no COLMAP: images are positions 0 .. num_images - 1.
//
// Each image is a sparse vector over the words: weight sqrt(tf) * idf, tf
// the times the image holds the word (the square root damps bursts, a
// facade's repeated windows voting once per window), idf = log(N / df)
// with df the images holding it (words every image holds say nothing;
// words in more than a given share of the images are dropped as stop
// words), then L2-normalised. The query side is the image's query words
// (num_nearest_neighbors cells per feature and table), weighted the same
// way. The similarity of query q to image j is the dot product of q's
// query vector with j's indexed vector, accumulated over the postings of
// q's words. docs/retrieval.md has the method and its cost.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include "cashash/retrieval/retrieval_options.h"
#include "cashash/retrieval/visual_words.h"

namespace cashash {

struct RetrievalNeighbor {
  uint32_t image = 0;  // position in the index
  float score = 0.f;   // cosine similarity of the tf-idf vectors, in (0, 1]
};

// One word of an image's query vector, and one posting of a word's list.
struct RetrievalQueryWord {
  uint32_t word;
  float weight;
};
struct RetrievalPosting {
  uint32_t image;
  float weight;
};

// Read-only view of an index's arrays, for a search that runs elsewhere
// (the GPU's, cuda/cashash_cuda/retrieval/image_retrieval_index.h); valid
// while the index lives.
struct RetrievalIndexView {
  size_t num_images = 0;
  uint32_t vocabulary_size = 0;
  // Query vector of image i: queries[query_offsets[i] .. query_offsets[i + 1]),
  // by word ascending; every word has a posting list.
  const size_t* query_offsets = nullptr;  // num_images + 1
  const RetrievalQueryWord* queries = nullptr;
  // Postings of word w: postings[posting_offsets[w] .. posting_offsets[w + 1]),
  // by image ascending; every weight > 0.
  const size_t* posting_offsets = nullptr;  // vocabulary_size + 1
  const RetrievalPosting* postings = nullptr;
  size_t num_query_words() const { return query_offsets[num_images]; }
  size_t num_postings() const { return posting_offsets[vocabulary_size]; }
};

// Whether `a` ranks before `b` in a neighbour list: score descending, then
// position ascending (the rule of every TopK, CPU and GPU).
inline bool RanksBefore(const RetrievalNeighbor& a, const RetrievalNeighbor& b) {
  return a.score != b.score ? a.score > b.score : a.image < b.image;
}

class ImageRetrievalIndex {
 public:
  // images[i] are the words of image i (its query words are its indexed
  // ones where `query` is empty); every word < vocabulary_size
  // (std::invalid_argument otherwise). Building uses num_threads threads
  // (-1: every core).
  // Move the words in to have each image's freed once it is counted.
  // Words held by more than max_word_image_fraction of the images (and
  // more than RetrievalOptions::kMinStopWordImages) are stop words: left
  // out of every vector.
  ImageRetrievalIndex(std::vector<ImageWords> images, uint32_t vocabulary_size, int num_threads = -1,
                      double max_word_image_fraction = 1.0);

  size_t num_images() const { return query_offsets_.size() - 1; }

  // The k images most similar to `image`, itself excluded, best first
  // (score descending, then position ascending, so the result is the same
  // on every run and thread count). Images sharing no word with it are
  // never returned, so there may be fewer than k.
  std::vector<RetrievalNeighbor> TopK(size_t image, size_t k) const;

  // TopK of every image, on num_threads threads.
  std::vector<std::vector<RetrievalNeighbor>> AllTopK(size_t k) const;

  // TopK of each of `images`, in that order, on num_threads threads.
  std::vector<std::vector<RetrievalNeighbor>> TopKOf(const std::vector<uint32_t>& images, size_t k) const;

  // Postings read by the queries of all images (the cost of AllTopK).
  uint64_t PostingsReadByAllQueries() const;

  // The arrays the queries read, for a search elsewhere (the GPU).
  RetrievalIndexView View() const;

 private:
  using WeightedWord = RetrievalQueryWord;
  using Posting = RetrievalPosting;

  std::vector<RetrievalNeighbor> TopKWithScratch(size_t image, size_t k, std::vector<float>* scores,
                                                 std::vector<uint32_t>* touched) const;

  int num_threads_ = -1;
  // Query vectors of all images, image i at [query_offsets_[i],
  // query_offsets_[i + 1]); only words some other image holds are kept.
  std::vector<size_t> query_offsets_;
  std::vector<WeightedWord> queries_;
  // Postings of word w at [posting_offsets_[w], posting_offsets_[w + 1]),
  // by image ascending; words of a single image have none.
  std::vector<size_t> posting_offsets_;
  std::vector<Posting> postings_;
};

// The pairs to match from each image's neighbours: every (image, neighbour)
// once, as (smaller position, larger position), sorted.
std::vector<std::pair<uint32_t, uint32_t>> UnionOfNeighborPairs(
    const std::vector<std::vector<RetrievalNeighbor>>& neighbors);

}  // namespace cashash
