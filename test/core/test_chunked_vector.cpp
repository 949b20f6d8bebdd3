// ChunkedVector: copies share chunks and stay as they were while the original changes (and the
// other way round), across chunk boundaries, truncation and growth; a random evolution against
// std::vector, with copies taken along the way.
#include "view_selection/core/chunked_vector.h"

#include <gtest/gtest.h>

#include <random>
#include <vector>

namespace view_selection::core {
namespace {

TEST(ChunkedVector, BehavesLikeAVectorAcrossChunkBoundaries) {
  ChunkedVector<int> v;
  std::vector<int> want;
  for (int i = 0; i < 1000; ++i) {
    v.push_back(i);
    want.push_back(i);
  }
  EXPECT_EQ(v.size(), 1000u);
  EXPECT_EQ(v.chunkCount(), (1000 + ChunkedVector<int>::kChunk - 1) / ChunkedVector<int>::kChunk);
  EXPECT_EQ(v, want);
  EXPECT_EQ(v.back(), 999);
  v.resize(300);
  want.resize(300);
  EXPECT_EQ(v, want);
  EXPECT_EQ(v.chunkCount(), 2u);
  v.resize(600, -1);
  want.resize(600, -1);
  EXPECT_EQ(v, want);
  EXPECT_EQ(v.toVector(), want);
  int sum = 0;
  for (const int x : v) sum += x;
  int want_sum = 0;
  for (const int x : want) want_sum += x;
  EXPECT_EQ(sum, want_sum);
}

TEST(ChunkedVector, CopiesStayAsTheyWereWhileEitherSideChanges) {
  std::mt19937 rng(7);
  std::uniform_int_distribution<int> value(0, 1000000);
  ChunkedVector<int> v;
  std::vector<int> model;
  std::vector<std::pair<ChunkedVector<int>, std::vector<int>>> copies;
  for (int step = 0; step < 4000; ++step) {
    const int op = value(rng) % 10;
    if (op < 5 || model.empty()) {
      const int x = value(rng);
      v.push_back(x);
      model.push_back(x);
    } else if (op < 8) {
      const size_t i = static_cast<size_t>(value(rng)) % model.size();
      const int x = value(rng);
      v.edit(i) = x;
      model[i] = x;
    } else if (op < 9) {
      const size_t n = static_cast<size_t>(value(rng)) % (model.size() + 300);
      v.resize(n, 5);
      model.resize(n, 5);
    } else {
      copies.emplace_back(v, model);  // a reader's copy
      if (copies.size() > 6) copies.erase(copies.begin());
      // A copy changed on its own side must leave the original alone.
      auto& [copy, copy_model] = copies.back();
      if (!copy_model.empty()) {
        copy.edit(0) = -7;
        copy_model[0] = -7;
      }
    }
    ASSERT_EQ(v, model) << "step " << step;
    for (const auto& [copy, copy_model] : copies) ASSERT_EQ(copy, copy_model) << "step " << step;
  }
}

TEST(ChunkedVector, ACopySharesEveryChunkUntilOneChanges) {
  ChunkedVector<int> v(2000, 1);
  const ChunkedVector<int> copy = v;
  EXPECT_EQ(&copy[0], &v[0]) << "a copy must share its chunks, not copy them";
  EXPECT_EQ(&copy[1999], &v[1999]);
  v.edit(1999) = 2;  // copies the last chunk only
  EXPECT_NE(&copy[1999], &v[1999]);
  EXPECT_EQ(&copy[0], &v[0]);
  EXPECT_EQ(copy[1999], 1);
  EXPECT_EQ(v[1999], 2);
}

}  // namespace
}  // namespace view_selection::core
