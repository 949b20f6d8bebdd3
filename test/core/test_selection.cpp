// Selection on hand-built matrices whose answers are worked out here by hand (METHOD.md "Next
// view sets", "View check", "Completion", "Outputs"), plus randomized invariants.
#include "view_selection/core/selection.h"

#include "view_selection/core/chunked_selection.h"
#include "view_selection/core/error_resistance.h"
#include "view_selection/core/exceptions.h"
#include "view_selection/core/pair_buckets.h"
#include "view_selection/core/selection_cache.h"

#include <gtest/gtest.h>

#include <queue>
#include <random>
#include <set>
#include "support/layers.h"

namespace view_selection {
namespace {

constexpr double X = kInfinity;
using Pairs = std::vector<std::pair<ViewId, ViewId>>;

TEST(Selection, TraversalTakesSecondBestWhenMarkedAndReturnsWhenAllMarked) {
  // k = 2.
  //   C0 = [2 (0.1), 1 (0.3)]   C1 = [0 (0.2), 3 (0.5)]   C2 = [1 (0.05), 0 (0.4)]   C3 = []
  // s = 2 (E[2][1] = 0.05 is the smallest entry). From 2: best unmarked is 1. From 1: 0.
  // At 0 both next views are marked (special case 2): return to 1, whose best (0) is marked, so
  // its second best 3 is taken (special case 1). 3 has no next views: back to 1, then 2, done.
  const auto e = ErrorResistanceTable::fromDense({
      {X, 0.3, 0.1, X},
      {0.2, X, X, 0.5},
      {0.4, 0.05, X, X},
      {X, X, X, X},
  });
  const Selection s = selectViews(e, {2, CompletionMode::kPaper});
  EXPECT_EQ(s.next_views, (std::vector<NextViewSet>{{2, 1}, {0, 3}, {1, 0}, {}}));
  EXPECT_EQ(s.start_view, 2);
  EXPECT_EQ(s.initialPair(), std::make_pair(2, 1));
  EXPECT_EQ(s.order, (std::vector<ViewId>{2, 1, 0, 3}));
  EXPECT_TRUE(s.completed.empty());
  EXPECT_TRUE(s.isolated.empty());
  EXPECT_EQ(s.final_next_views, s.next_views);
  EXPECT_EQ(s.pairs, (Pairs{{0, 1}, {0, 2}, {1, 2}, {1, 3}}));
}

// Seven views, k = 1.
//   row 0: E01 = 0.1, E06 = 0.8      C0 = [1]
//   row 1: E10 = 0.2, E12 = 0.9      C1 = [0]
//   row 2: E23 = 0.25                C2 = [3]
//   row 3: E34 = 0.4                 C3 = [4]
//   row 4: E42 = 0.35                C4 = [2]
//   rows 5, 6: nothing               C5 = C6 = []
// s = 0; traversal 0 -> 1, and 1's only next view (0) is marked: order [0, 1].
ErrorResistanceTable sevenViews() {
  return ErrorResistanceTable::fromDense({
      {X, 0.1, X, X, X, X, 0.8},
      {0.2, X, 0.9, X, X, X, X},
      {X, X, X, 0.25, X, X, X},
      {X, X, X, X, 0.4, X, X},
      {X, X, 0.35, X, X, X, X},
      {X, X, X, X, X, X, X},
      {X, X, X, X, X, X, X},
  });
}

TEST(Selection, PaperCompletionAddsEachMissedViewToItsBestPredecessor) {
  // Unvisited 2..6 in increasing id; the best predecessor is over all views:
  //   2: column {E12 = 0.9, E42 = 0.35} -> 4 (already in C4: set unchanged, completion recorded)
  //   3: column {E23} -> 2 (already there)   4: {E34} -> 3 (already there)
  //   5: empty column -> isolated            6: {E06} -> 0, C0 becomes [1, 6]
  // Paper mode does not extend the order, and 2, 3, 4 stay unreachable from s = 0.
  const Selection s = selectViews(sevenViews(), {1, CompletionMode::kPaper});
  EXPECT_EQ(s.next_views, (std::vector<NextViewSet>{{1}, {0}, {3}, {4}, {2}, {}, {}}));
  EXPECT_EQ(s.start_view, 0);
  EXPECT_EQ(s.order, (std::vector<ViewId>{0, 1}));
  EXPECT_EQ(s.completed, (std::vector<CompletedView>{{2, 4}, {3, 2}, {4, 3}, {6, 0}}));
  EXPECT_EQ(s.isolated, (std::vector<ViewId>{5}));
  EXPECT_EQ(s.final_next_views, (std::vector<NextViewSet>{{1, 6}, {0}, {3}, {4}, {2}, {}, {}}));
  EXPECT_EQ(s.pairs, (Pairs{{0, 1}, {0, 6}, {2, 3}, {2, 4}, {3, 4}}));
}

TEST(Selection, ReachableCompletionJoinsFromVisitedViewsAndContinuesTraversal) {
  // Visited {0, 1}; candidates (unvisited with a finite entry from a visited view): {2, 6}.
  //   2: visited predecessors {E12 = 0.9} (4 is not visited) -> C1 = [0, 2]; traversal continues
  //      from 2: 2 -> 3 -> 4 (4's next view 2 is marked). order [0, 1, 2, 3, 4]
  //   6: {E06} -> C0 = [1, 6]; 6 has no next views. order [..., 6]
  //   5 is unreachable: isolated.
  const Selection s = selectViews(sevenViews(), {1, CompletionMode::kReachable});
  EXPECT_EQ(s.order, (std::vector<ViewId>{0, 1, 2, 3, 4, 6}));
  EXPECT_EQ(s.completed, (std::vector<CompletedView>{{2, 1}, {6, 0}}));
  EXPECT_EQ(s.isolated, (std::vector<ViewId>{5}));
  EXPECT_EQ(s.final_next_views, (std::vector<NextViewSet>{{1, 6}, {0, 2}, {3}, {4}, {2}, {}, {}}));
  EXPECT_EQ(s.pairs, (Pairs{{0, 1}, {0, 6}, {1, 2}, {2, 3}, {2, 4}, {3, 4}}));
  // Next view sets before completion do not depend on the mode.
  EXPECT_EQ(s.next_views, selectViews(sevenViews(), {1, CompletionMode::kPaper}).next_views);
}

TEST(Selection, TiesBreakOnLowerId) {
  // Row 0 ties 1 and 2 at 0.5; the start ties E03 = E10 = 0.2, so the lower row (0) wins.
  const auto e = ErrorResistanceTable::fromDense({
      {X, 0.5, 0.5, 0.2},
      {0.2, X, 0.7, 0.7},
      {X, X, X, X},
      {X, X, X, X},
  });
  const Selection s = selectViews(e, {2, CompletionMode::kPaper});
  EXPECT_EQ(s.next_views[0], (NextViewSet{3, 1}));
  EXPECT_EQ(s.next_views[1], (NextViewSet{0, 2}));
  EXPECT_EQ(s.start_view, 0);
  EXPECT_EQ(findStartView(e), 0);
  // Order: 0 -> 3 (nothing) -> back, 0 -> 1 -> 2 (0 marked), back. Ties again on ids.
  EXPECT_EQ(s.order, (std::vector<ViewId>{0, 3, 1, 2}));
}

TEST(Selection, DegenerateMatrices) {
  const Selection empty = selectViews(ErrorResistanceTable(0), {});
  EXPECT_EQ(empty.start_view, -1);
  EXPECT_TRUE(empty.order.empty() && empty.pairs.empty() && empty.isolated.empty());
  EXPECT_EQ(empty.initialPair(), std::make_pair(-1, -1));

  for (const CompletionMode mode : {CompletionMode::kPaper, CompletionMode::kReachable}) {
    const Selection none = selectViews(ErrorResistanceTable(3), {5, mode});
    EXPECT_EQ(none.start_view, -1);
    EXPECT_TRUE(none.order.empty());
    EXPECT_EQ(none.isolated, (std::vector<ViewId>{0, 1, 2}));
    EXPECT_TRUE(none.pairs.empty());
  }
  EXPECT_THROW(selectViews(ErrorResistanceTable(2), {0, CompletionMode::kPaper}), InvalidArgument);
  EXPECT_EQ(completionModeFromString("reachable"), CompletionMode::kReachable);
  EXPECT_THROW(completionModeFromString("Paper"), InvalidArgument);
}

TEST(Selection, TableKeepsRowsAndColumnsConsistent) {
  ErrorResistanceTable t(4);
  t.set(0, 2, 1.0);
  t.set(3, 2, 0.5);
  t.set(0, 0, 7.0);  // the diagonal is never stored
  EXPECT_EQ(t.at(0, 0), kInfinity);
  EXPECT_EQ(t.finiteCount(), 2u);
  ASSERT_EQ(t.column(2).size(), 2u);
  EXPECT_EQ(t.column(2)[0].view, 0);
  EXPECT_EQ(t.column(2)[1].view, 3);
  t.set(0, 2, kInfinity);
  EXPECT_EQ(t.finiteCount(), 1u);
  EXPECT_EQ(t.column(2).size(), 1u);
  t.replaceRow(3, {{1, 0.25}, {0, 0.75}});
  EXPECT_EQ(t.column(2).size(), 0u);
  EXPECT_EQ(t.at(3, 0), 0.75);
  EXPECT_EQ(t.finiteCount(), 2u);
  EXPECT_EQ(t.dense()[3], (std::vector<double>{0.75, 0.25, X, X}));
}

/// Views reachable from `from` through `sets`.
std::set<ViewId> reachable(const std::vector<NextViewSet>& sets, ViewId from) {
  std::set<ViewId> seen{from};
  std::queue<ViewId> queue;
  queue.push(from);
  while (!queue.empty()) {
    const ViewId v = queue.front();
    queue.pop();
    for (const ViewId w : sets[static_cast<size_t>(v)])
      if (seen.insert(w).second) queue.push(w);
  }
  return seen;
}

TEST(Selection, RandomMatricesKeepTheInvariants) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> uni(0.0, 1.0);
  for (int trial = 0; trial < 300; ++trial) {
    const size_t n = 1 + static_cast<size_t>(uni(rng) * 40);
    const double density = uni(rng) * 0.3;
    std::vector<std::vector<double>> dense(n, std::vector<double>(n, X));
    for (size_t i = 0; i < n; ++i)
      for (size_t j = 0; j < n; ++j)
        if (i != j && uni(rng) < density) dense[i][j] = std::round(uni(rng) * 20) / 20;  // ties
    const auto e = ErrorResistanceTable::fromDense(dense);
    const int k = 1 + static_cast<int>(uni(rng) * 5);
    for (const CompletionMode mode : {CompletionMode::kPaper, CompletionMode::kReachable}) {
      const Selection s = selectViews(e, {k, mode});
      // Sets: at most k, finite entries, sorted by (value, id).
      for (size_t i = 0; i < n; ++i) {
        const auto& c = s.next_views[i];
        ASSERT_LE(c.size(), static_cast<size_t>(k));
        ASSERT_EQ(c.size(), std::min(static_cast<size_t>(k), e.row(static_cast<ViewId>(i)).size()));
        for (size_t q = 1; q < c.size(); ++q) {
          const double a = e.at(static_cast<ViewId>(i), c[q - 1]),
                       b = e.at(static_cast<ViewId>(i), c[q]);
          ASSERT_TRUE(a < b || (a == b && c[q - 1] < c[q]));
        }
        // ... and they are the k best of the row: a full sort of the row agrees.
        std::vector<TableEntry> row = e.row(static_cast<ViewId>(i));
        std::sort(row.begin(), row.end(), [](const TableEntry& a, const TableEntry& b) {
          return a.value < b.value || (a.value == b.value && a.view < b.view);
        });
        for (size_t q = 0; q < c.size(); ++q) ASSERT_EQ(c[q], row[q].view) << "trial " << trial;
      }
      // The start view taken from the sets is the row of E's smallest entry (full scan).
      ASSERT_EQ(s.start_view, findStartView(e)) << "trial " << trial;
      // Order is a list of distinct views; every view is visited or isolated or completed.
      const std::set<ViewId> ordered(s.order.begin(), s.order.end());
      ASSERT_EQ(ordered.size(), s.order.size());
      std::set<ViewId> covered = ordered;
      for (const auto& c : s.completed) covered.insert(c.view);
      for (const ViewId v : s.isolated) {
        ASSERT_EQ(covered.count(v), 0u);
        covered.insert(v);
      }
      ASSERT_EQ(covered.size(), n);
      if (s.start_view < 0) continue;
      ASSERT_EQ(s.order.front(), s.start_view);
      if (mode == CompletionMode::kReachable) {
        // Every non-isolated view is reachable from s through the final sets.
        const std::set<ViewId> r = reachable(s.final_next_views, s.start_view);
        ASSERT_EQ(r.size() + s.isolated.size(), n) << "trial " << trial;
        ASSERT_EQ(r, ordered);
      } else {
        // Paper mode: a completed view is in its predecessor's final set, and no view with a
        // finite column entry is left out.
        for (const auto& c : s.completed) {
          const auto& f = s.final_next_views[static_cast<size_t>(c.added_to)];
          ASSERT_NE(std::find(f.begin(), f.end(), c.view), f.end());
          for (const TableEntry& entry : e.column(c.view))
            ASSERT_GE(entry.value, e.at(c.added_to, c.view));
        }
        for (const ViewId v : s.isolated) ASSERT_TRUE(e.column(v).empty());
      }
      // Pairs: the undirected union of the final sets.
      std::set<std::pair<ViewId, ViewId>> expected;
      for (size_t i = 0; i < n; ++i)
        for (const ViewId j : s.final_next_views[i])
          expected.insert({std::min<ViewId>(static_cast<ViewId>(i), j),
                           std::max<ViewId>(static_cast<ViewId>(i), j)});
      ASSERT_EQ(s.pairs, Pairs(expected.begin(), expected.end()));
    }
  }
}

TEST(Selection, TableKeepsEachRowsBestEntriesThroughEveryKindOfChange) {
  // The cached best entries of each row must equal a full sort of the row after any sequence of
  // inserts, improvements, worsenings, removals and row replacements.
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> uni(0.0, 1.0);
  const size_t n = 30;
  ErrorResistanceTable e(n);
  auto check = [&](int step) {
    for (size_t i = 0; i < n; ++i) {
      std::vector<TableEntry> row = e.row(static_cast<ViewId>(i));
      std::sort(row.begin(), row.end(), [](const TableEntry& a, const TableEntry& b) {
        return a.value < b.value || (a.value == b.value && a.view < b.view);
      });
      row.resize(std::min(row.size(), ErrorResistanceTable::kTopCapacity));
      ASSERT_EQ(e.top(static_cast<ViewId>(i)), row) << "row " << i << " after step " << step;
    }
  };
  for (int step = 0; step < 4000; ++step) {
    const auto i = static_cast<ViewId>(uni(rng) * n);
    const auto j = static_cast<ViewId>(uni(rng) * n);
    const double op = uni(rng);
    if (op < 0.65) {
      e.set(i, j, std::round(uni(rng) * 30) / 30);  // ties on purpose
    } else if (op < 0.95) {
      e.set(i, j, kInfinity);
    } else {
      std::vector<TableEntry> entries;
      for (size_t q = 0; q < n; ++q)
        if (uni(rng) < 0.5)
          entries.push_back({static_cast<ViewId>(q), std::round(uni(rng) * 30) / 30});
      e.replaceRow(i, entries);
    }
    ASSERT_NO_FATAL_FAILURE(check(step));  // the first wrong row stops the walk
  }
  // Larger k than the cache holds takes the scan: the same sets as a full sort.
  const Selection s = selectViews(
      e, {static_cast<int>(ErrorResistanceTable::kTopCapacity) + 4, CompletionMode::kPaper});
  for (size_t i = 0; i < n; ++i) {
    std::vector<TableEntry> row = e.row(static_cast<ViewId>(i));
    std::sort(row.begin(), row.end(), [](const TableEntry& a, const TableEntry& b) {
      return a.value < b.value || (a.value == b.value && a.view < b.view);
    });
    row.resize(std::min(row.size(), ErrorResistanceTable::kTopCapacity + 4));
    ASSERT_EQ(s.next_views[i].size(), row.size());
    for (size_t q = 0; q < row.size(); ++q) ASSERT_EQ(s.next_views[i][q], row[q].view);
  }
}

void expectSameSelection(const Selection& got, const Selection& want, const std::string& where) {
  EXPECT_EQ(got.next_views, want.next_views) << where;
  EXPECT_EQ(got.final_next_views, want.final_next_views) << where;
  EXPECT_EQ(got.start_view, want.start_view) << where;
  EXPECT_EQ(got.order, want.order) << where;
  EXPECT_EQ(got.completed, want.completed) << where;
  EXPECT_EQ(got.isolated, want.isolated) << where;
  EXPECT_EQ(got.pairs, want.pairs) << where;
}

void expectSameSelection(const ChunkedSelection& got, const Selection& want,
                         const std::string& where) {
  expectSameSelection(got.toSelection(), want, where);
  EXPECT_EQ(got.pairs.size(), want.pairs.size()) << where;
}

/// Follows a cache's pair changes: applied to the pairs before, they must give the pairs now.
struct PairFollower {
  std::set<std::pair<ViewId, ViewId>> pairs;
  void apply(const PairChanges& c, const std::string& where) {
    for (const auto& p : c.removed) EXPECT_EQ(pairs.erase(p), 1u) << where << ": removed twice";
    for (const auto& p : c.added) EXPECT_TRUE(pairs.insert(p).second) << where << ": added twice";
  }
  void expectEqual(const std::vector<std::pair<ViewId, ViewId>>& want, const std::string& where) {
    const std::vector<std::pair<ViewId, ViewId>> followed(pairs.begin(), pairs.end());
    EXPECT_EQ(followed, want) << where;
  }
};

TEST(Selection, CacheEqualsFullSelectionAfterAnySequenceOfChanges) {
  // The incremental path against the plain definition, after every step of a random evolution:
  // keyframes added (growing tables, entries toward and from the new view), entries changed and
  // removed (rows recomputed), whole rows replaced, parameters changed, a reset. Sparse tables
  // leave views unreached, so completion runs in both modes; ties are frequent on purpose.
  std::mt19937 rng(2024);
  std::uniform_real_distribution<double> uni(0.0, 1.0);
  int completed_seen = 0, isolated_seen = 0;
  size_t resumed = 0;
  for (const int k : {1, 2, 5, 20}) {
    for (const CompletionMode mode : {CompletionMode::kPaper, CompletionMode::kReachable}) {
      const SelectionConfig config{k, mode};
      ErrorResistanceTable e;
      SelectionCache cache;
      cache.trackPairChanges(true);
      PairFollower follower;
      // A copy of an earlier result, as a reader holds it: later updates must not change it.
      ChunkedSelection held;
      Selection held_plain;
      for (int step = 0; step < 400; ++step) {
        const double op = uni(rng);
        const size_t n = e.size();
        if (n < 3 || op < 0.3) {  // a new keyframe with a few entries each way
          e.resize(n + 1);
          const auto added = static_cast<ViewId>(n);
          for (size_t q = 0; q < n; ++q) {
            if (uni(rng) < 0.15) e.set(added, static_cast<ViewId>(q), std::round(uni(rng) * 20) / 20);
            if (uni(rng) < 0.15) e.set(static_cast<ViewId>(q), added, std::round(uni(rng) * 20) / 20);
          }
        } else if (op < 0.75) {
          const auto i = static_cast<ViewId>(uni(rng) * n), j = static_cast<ViewId>(uni(rng) * n);
          e.set(i, j, uni(rng) < 0.7 ? std::round(uni(rng) * 20) / 20 : kInfinity);
        } else if (op < 0.95) {
          std::vector<TableEntry> entries;
          for (size_t q = 0; q < n; ++q)
            if (uni(rng) < 0.1) entries.push_back({static_cast<ViewId>(q), std::round(uni(rng) * 20) / 20});
          e.replaceRow(static_cast<ViewId>(uni(rng) * n), entries);
        } else if (op < 0.98) {  // the same table under other parameters and back
          const SelectionConfig other{k == 1 ? 3 : 1, mode};
          expectSameSelection(cache.update(e, other), selectViews(e, other), "other config");
        } else {
          e.clear();
        }
        const ChunkedSelection& got = cache.update(e, config);
        const Selection want = selectViews(e, config);
        const std::string where = "k " + std::to_string(k) + " mode " + toString(mode) +
                                  " step " + std::to_string(step) + " n " +
                                  std::to_string(e.size());
        expectSameSelection(got, want, where);
        follower.apply(cache.takePairChanges(), where);
        follower.expectEqual(want.pairs, where + ": the pairs followed through their changes");
        expectSameSelection(held, held_plain, where + ": a copy held from the step before");
        held = got;
        held_plain = want;
        if (::testing::Test::HasFailure()) return;
        completed_seen += static_cast<int>(!want.completed.empty());
        isolated_seen += static_cast<int>(!want.isolated.empty());
      }
      resumed += cache.resumedUpdates();
    }
  }
  EXPECT_GT(resumed, 50u) << "the resumed completion must be exercised here too";
  // Both completion paths and isolated views must have been exercised.
  EXPECT_GT(completed_seen, 100);
  EXPECT_GT(isolated_seen, 100);
}

TEST(Selection, ResumedCompletionEqualsFullSelectionAlongAWalk) {
  // A SLAM walk: each new keyframe has entries to and from the keyframes near it along the
  // walk (and, now and then, a revisit far back), so most updates change rows near the end of
  // the traversal and completion is resumed there, sometimes inside a completion's traversal.
  // Now and then a loop closure rewrites a row far back (resumed earlier, or redone). After
  // every update the cache must equal the plain definition.
  std::mt19937 rng(99);
  std::uniform_real_distribution<double> uni(0.0, 1.0);
  size_t resumed = 0, inside = 0, updates = 0;
  for (const int k : {1, 3, 5}) {
    const SelectionConfig config{k, CompletionMode::kReachable};
    ErrorResistanceTable e;
    SelectionCache cache;
    cache.trackPairChanges(true);
    PairFollower follower;
    for (int step = 0; step < 600; ++step) {
      const size_t n = e.size();
      e.resize(n + 1);
      const auto added = static_cast<ViewId>(n);
      const size_t width = 2 + static_cast<size_t>(uni(rng) * 6);
      for (size_t q = n > width ? n - width : 0; q < n; ++q) {
        if (uni(rng) < 0.6) e.set(added, static_cast<ViewId>(q), 0.5 + uni(rng));
        if (uni(rng) < 0.6) e.set(static_cast<ViewId>(q), added, 0.5 + uni(rng));
      }
      if (n > 20 && uni(rng) < 0.05) {  // a revisit: entries to a view far back
        const auto back = static_cast<ViewId>(uni(rng) * (n - 10));
        e.set(added, back, 0.5 + uni(rng));
        e.set(back, added, 0.5 + uni(rng));
      }
      if (n > 20 && uni(rng) < 0.03) {  // a loop closure rewrote an old row
        const auto old = static_cast<ViewId>(uni(rng) * n);
        std::vector<TableEntry> entries;
        for (size_t q = 0; q < n; ++q)
          if (q != static_cast<size_t>(old) && uni(rng) < 3.0 / static_cast<double>(n))
            entries.push_back({static_cast<ViewId>(q), 0.5 + uni(rng)});
        e.replaceRow(old, entries);
      }
      const std::string where = "k " + std::to_string(k) + " step " + std::to_string(step);
      const Selection want = selectViews(e, config);
      expectSameSelection(cache.update(e, config), want, where);
      follower.apply(cache.takePairChanges(), where);
      follower.expectEqual(want.pairs, where + ": the pairs followed through their changes");
      if (::testing::Test::HasFailure()) return;
    }
    resumed += cache.resumedUpdates();
    inside += cache.resumedInsideTraversal();
    updates += cache.updates();
  }
  // The resumed paths must be what ran most of the time, both kinds of them.
  EXPECT_GT(resumed, updates / 2) << resumed << " of " << updates;
  EXPECT_GT(inside, 20u);
  EXPECT_LT(resumed, updates) << "some updates must redo the traversal";
}

TEST(Selection, CacheFollowsACopiedTable) {
  // Row versions are unique across tables: a cache fed a copy, then the original changed in
  // another way, still gives the definition's answer.
  ErrorResistanceTable a(4);
  a.set(0, 1, 1.0);
  a.set(1, 2, 2.0);
  a.set(2, 3, 3.0);
  ErrorResistanceTable b = a;
  SelectionCache cache;
  const SelectionConfig config{2, CompletionMode::kReachable};
  cache.update(a, config);
  b.set(0, 1, kInfinity);
  b.set(0, 3, 0.5);
  expectSameSelection(cache.update(b, config), selectViews(b, config), "copy changed");
  a.set(3, 0, 0.25);
  expectSameSelection(cache.update(a, config), selectViews(a, config), "original changed");
}

TEST(Selection, TableCopiesStayAsTheyWereWhileTheOriginalChanges) {
  // Copies share their lists with the original until one side changes (copy on write): every
  // copy must keep exactly the entries, columns and best entries it had when taken, whatever
  // happens to the original or to other copies afterwards.
  std::mt19937 rng(77);
  std::uniform_real_distribution<double> uni(0.0, 1.0);
  const size_t n = 25;
  ErrorResistanceTable e(n);
  struct Kept {
    ErrorResistanceTable copy;
    std::vector<std::vector<double>> dense;
    std::vector<std::vector<TableEntry>> columns, tops;
  };
  auto capture = [&](const ErrorResistanceTable& t) {
    Kept k{t, t.dense(), {}, {}};
    for (size_t i = 0; i < n; ++i) {
      k.columns.push_back(t.column(static_cast<ViewId>(i)));
      k.tops.push_back(t.top(static_cast<ViewId>(i)));
    }
    return k;
  };
  auto same = [&](const Kept& k, const ErrorResistanceTable& t) {
    if (t.dense() != k.dense) return false;
    for (size_t i = 0; i < n; ++i)
      if (t.column(static_cast<ViewId>(i)) != k.columns[i] || t.top(static_cast<ViewId>(i)) != k.tops[i])
        return false;
    return true;
  };
  std::vector<Kept> kept;
  for (int step = 0; step < 3000; ++step) {
    const auto i = static_cast<ViewId>(uni(rng) * n), j = static_cast<ViewId>(uni(rng) * n);
    const double op = uni(rng);
    if (op < 0.6) {
      e.set(i, j, std::round(uni(rng) * 30) / 30);
    } else if (op < 0.9) {
      e.set(i, j, kInfinity);
    } else if (op < 0.95) {
      std::vector<TableEntry> entries;
      for (size_t q = 0; q < n; ++q)
        if (uni(rng) < 0.3) entries.push_back({static_cast<ViewId>(q), uni(rng)});
      e.replaceRow(i, entries);
    } else if (!kept.empty() && op < 0.97) {
      // A copy changes too: neither the original nor the other copies may see it.
      const Kept before = capture(e);
      Kept& victim = kept[static_cast<size_t>(uni(rng) * kept.size())];
      victim.copy.set(i, j, 0.5);
      victim = capture(victim.copy);
      ASSERT_TRUE(same(before, e)) << "a change to a copy reached the original at step " << step;
    } else {
      kept.push_back(capture(e));
    }
    for (size_t q = 0; q < kept.size(); ++q)
      ASSERT_TRUE(same(kept[q], kept[q].copy)) << "copy " << q << " changed at step " << step;
  }
  EXPECT_GT(kept.size(), 50u);
}

}  // namespace
}  // namespace view_selection
