#include "cashash/retrieval/image_retrieval_index.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

#include "cashash/base/parallel_for.h"

namespace cashash {
namespace {

struct WordCount {
  uint32_t word;
  uint32_t count;
};

// (word, times it occurs) of `words`, by word ascending.
std::vector<WordCount> CountWords(std::vector<uint32_t> words) {
  std::sort(words.begin(), words.end());
  std::vector<WordCount> counts;
  for (size_t i = 0; i < words.size();) {
    size_t j = i;
    while (j < words.size() && words[j] == words[i]) ++j;
    counts.push_back({words[i], static_cast<uint32_t>(j - i)});
    i = j;
  }
  return counts;
}

}  // namespace

ImageRetrievalIndex::ImageRetrievalIndex(std::vector<ImageWords> images, uint32_t vocabulary_size, int num_threads,
                                         double max_word_image_fraction)
    : num_threads_(num_threads) {
  const size_t n = images.size();
  for (size_t i = 0; i < n; ++i) {
    for (const std::vector<uint32_t>* words : {&images[i].indexed, &images[i].query}) {
      for (uint32_t word : *words) {
        if (word >= vocabulary_size) {
          throw std::invalid_argument("ImageRetrievalIndex: image " + std::to_string(i) + " has word " +
                                      std::to_string(word) + " past the vocabulary of " +
                                      std::to_string(vocabulary_size));
        }
      }
    }
  }
  std::vector<std::vector<WordCount>> indexed(n), query(n);
  ParallelFor(n, num_threads, [&](size_t i) {
    // Moved: the words are freed once counted.
    indexed[i] = CountWords(std::move(images[i].indexed));
    if (!images[i].query.empty()) query[i] = CountWords(std::move(images[i].query));
  });

  // The vocabulary is cut into ranges of words, each range done by one
  // thread over every image (each image's counts are sorted by word, so
  // its part of a range is found by binary search): counting and filling
  // the postings scatter over arrays as large as the vocabulary, and this
  // way each thread scatters into a slice of its own.
  const size_t num_ranges = 8 * NumParallelWorkers(std::max<size_t>(n, 1), num_threads);
  auto range_begin = [&](size_t r) {
    return static_cast<uint32_t>(static_cast<uint64_t>(vocabulary_size) * r / num_ranges);
  };
  auto for_each_in_range = [&](size_t r, auto&& visit) {
    const uint32_t w0 = range_begin(r), w1 = range_begin(r + 1);
    for (size_t i = 0; i < n; ++i) {
      const std::vector<WordCount>& counts = indexed[i];
      auto it = std::lower_bound(counts.begin(), counts.end(), w0,
                                 [](const WordCount& c, uint32_t w) { return c.word < w; });
      for (; it != counts.end() && it->word < w1; ++it) visit(i, *it);
    }
  };

  // Document frequencies and idf over the indexed words. Stop words (in
  // more than max_word_image_fraction of the images, and more than
  // kMinStopWordImages: a point seen by tens of images is no stop word)
  // get idf 0: they say little about which images overlap and their
  // postings would be most of what the queries read.
  std::vector<uint32_t> df(vocabulary_size, 0);
  std::vector<float> idf(vocabulary_size, 0.f);
  const double stop_df =
      std::max<double>(RetrievalOptions::kMinStopWordImages, max_word_image_fraction * static_cast<double>(n));
  ParallelFor(num_ranges, num_threads, [&](size_t r) {
    for_each_in_range(r, [&](size_t, const WordCount& c) { ++df[c.word]; });
    for (uint32_t w = range_begin(r); w < range_begin(r + 1); ++w) {
      if (df[w] > 0 && df[w] <= stop_df) idf[w] = static_cast<float>(std::log(static_cast<double>(n) / df[w]));
    }
  });

  // Postings: sqrt(tf) * idf, normalised per image; by image ascending.
  std::vector<double> scale(n, 0.0);
  ParallelFor(n, num_threads, [&](size_t i) {
    double norm2 = 0;
    for (const WordCount& c : indexed[i]) {
      const double v = std::sqrt(static_cast<double>(c.count)) * idf[c.word];
      norm2 += v * v;
    }
    scale[i] = norm2 > 0 ? 1.0 / std::sqrt(norm2) : 0.0;
  });
  posting_offsets_.assign(static_cast<size_t>(vocabulary_size) + 1, 0);
  for (uint32_t w = 0; w < vocabulary_size; ++w) {
    posting_offsets_[w + 1] = posting_offsets_[w] + (idf[w] > 0.f ? df[w] : 0);
  }
  postings_.resize(posting_offsets_.back());
  ParallelFor(num_ranges, num_threads, [&](size_t r) {
    // df now counts the postings written.
    std::fill(df.begin() + range_begin(r), df.begin() + range_begin(r + 1), 0u);
    for_each_in_range(r, [&](size_t i, const WordCount& c) {
      if (idf[c.word] <= 0.f) return;
      const double v = std::sqrt(static_cast<double>(c.count)) * idf[c.word] * scale[i];
      postings_[posting_offsets_[c.word] + df[c.word]++] = {static_cast<uint32_t>(i), static_cast<float>(v)};
    });
  });

  // Query vectors, the same weighting over the query words; words no image
  // holds, or whose idf is 0 (every image holds them), score nothing. Each
  // image's counts are freed as soon as its query is written, so the
  // counts, the postings and the queries are never all held at once.
  query_offsets_.assign(n + 1, 0);
  auto query_words = [&](size_t i) -> const std::vector<WordCount>& {
    return query[i].empty() ? indexed[i] : query[i];
  };
  auto scores = [&](const WordCount& c) { return idf[c.word] > 0.f; };
  std::vector<size_t> sizes(n, 0);
  ParallelFor(n, num_threads, [&](size_t i) {
    for (const WordCount& c : query_words(i)) sizes[i] += scores(c);
  });
  for (size_t i = 0; i < n; ++i) query_offsets_[i + 1] = query_offsets_[i] + sizes[i];
  queries_.resize(query_offsets_.back());
  ParallelFor(n, num_threads, [&](size_t i) {
    const std::vector<WordCount>& words = query_words(i);
    double norm2 = 0;
    for (const WordCount& c : words) {
      const double v = std::sqrt(static_cast<double>(c.count)) * idf[c.word];
      norm2 += v * v;
    }
    const double scale = norm2 > 0 ? 1.0 / std::sqrt(norm2) : 0.0;
    size_t out = query_offsets_[i];
    for (const WordCount& c : words) {
      if (!scores(c)) continue;
      const double v = std::sqrt(static_cast<double>(c.count)) * idf[c.word] * scale;
      queries_[out++] = {c.word, static_cast<float>(v)};
    }
    std::vector<WordCount>().swap(query[i]);
    std::vector<WordCount>().swap(indexed[i]);
  });
}

std::vector<RetrievalNeighbor> ImageRetrievalIndex::TopKWithScratch(size_t image, size_t k, std::vector<float>* scores,
                                                                    std::vector<uint32_t>* touched) const {
  if (image >= num_images()) {
    throw std::out_of_range("ImageRetrievalIndex::TopK: image " + std::to_string(image) + " of " +
                            std::to_string(num_images()));
  }
  scores->resize(num_images(), 0.f);
  touched->clear();
  const size_t end = query_offsets_[image + 1];
  for (size_t q = query_offsets_[image]; q < end; ++q) {
    // Each word's postings lie at an unrelated place of a large array:
    // ask for those a few words ahead while these are added up.
    constexpr size_t kPrefetchWords = 8;
    if (q + kPrefetchWords < end) {
      const uint32_t ahead = queries_[q + kPrefetchWords].word;
      __builtin_prefetch(&posting_offsets_[ahead]);
      if (q + 2 * kPrefetchWords < end) {
        __builtin_prefetch(&postings_[posting_offsets_[queries_[q + kPrefetchWords / 2].word]]);
      }
    }
    const WeightedWord& word = queries_[q];
    for (size_t p = posting_offsets_[word.word]; p < posting_offsets_[word.word + 1]; ++p) {
      const Posting& posting = postings_[p];
      float& score = (*scores)[posting.image];
      if (score == 0.f) touched->push_back(posting.image);
      score += word.weight * posting.weight;
    }
  }
  std::vector<RetrievalNeighbor> candidates;
  candidates.reserve(touched->size());
  for (uint32_t j : *touched) {
    const float score = (*scores)[j];
    (*scores)[j] = 0.f;
    if (j != image && score > 0.f) candidates.push_back({j, score});
  }
  // Every weight read is > 0 (query words of idf 0 are dropped), so an
  // image is touched once per query.
  std::sort(candidates.begin(), candidates.end(), RanksBefore);
  if (candidates.size() > k) candidates.resize(k);
  return candidates;
}

std::vector<RetrievalNeighbor> ImageRetrievalIndex::TopK(size_t image, size_t k) const {
  std::vector<float> scores;
  std::vector<uint32_t> touched;
  return TopKWithScratch(image, k, &scores, &touched);
}

std::vector<std::vector<RetrievalNeighbor>> ImageRetrievalIndex::AllTopK(size_t k) const {
  const size_t n = num_images();
  std::vector<std::vector<RetrievalNeighbor>> result(n);
  const size_t workers = NumParallelWorkers(n, num_threads_);
  std::vector<std::vector<float>> scores(workers);
  std::vector<std::vector<uint32_t>> touched(workers);
  ParallelForWorkers(n, num_threads_, [&](size_t i, size_t worker) {
    result[i] = TopKWithScratch(i, k, &scores[worker], &touched[worker]);
  });
  return result;
}

std::vector<std::vector<RetrievalNeighbor>> ImageRetrievalIndex::TopKOf(const std::vector<uint32_t>& images,
                                                                        size_t k) const {
  std::vector<std::vector<RetrievalNeighbor>> result(images.size());
  const size_t workers = NumParallelWorkers(images.size(), num_threads_);
  std::vector<std::vector<float>> scores(workers);
  std::vector<std::vector<uint32_t>> touched(workers);
  ParallelForWorkers(images.size(), num_threads_, [&](size_t q, size_t worker) {
    result[q] = TopKWithScratch(images[q], k, &scores[worker], &touched[worker]);
  });
  return result;
}

uint64_t ImageRetrievalIndex::PostingsReadByAllQueries() const {
  uint64_t total = 0;
  for (const WeightedWord& word : queries_) total += posting_offsets_[word.word + 1] - posting_offsets_[word.word];
  return total;
}

RetrievalIndexView ImageRetrievalIndex::View() const {
  RetrievalIndexView view;
  view.num_images = num_images();
  view.vocabulary_size = static_cast<uint32_t>(posting_offsets_.size() - 1);
  view.query_offsets = query_offsets_.data();
  view.queries = queries_.data();
  view.posting_offsets = posting_offsets_.data();
  view.postings = postings_.data();
  return view;
}

std::vector<std::pair<uint32_t, uint32_t>> UnionOfNeighborPairs(
    const std::vector<std::vector<RetrievalNeighbor>>& neighbors) {
  std::vector<std::pair<uint32_t, uint32_t>> pairs;
  for (size_t i = 0; i < neighbors.size(); ++i) {
    for (const RetrievalNeighbor& neighbor : neighbors[i]) {
      const uint32_t a = static_cast<uint32_t>(i);
      pairs.emplace_back(std::min(a, neighbor.image), std::max(a, neighbor.image));
    }
  }
  std::sort(pairs.begin(), pairs.end());
  pairs.erase(std::unique(pairs.begin(), pairs.end()), pairs.end());
  return pairs;
}

}  // namespace cashash
