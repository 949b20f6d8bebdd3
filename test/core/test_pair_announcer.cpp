// The pair stream's stability rule (core::PairAnnouncer): a pair is announced once it is still
// selected m keyframes later; one that goes before costs nothing; one that goes after is taken
// back; flush() announces what waits. Also against a replay of a real selection: what a consumer
// that applies every announcement holds after the final flush is exactly the final selection.
#include "view_selection/core/pair_announcer.h"

#include <gtest/gtest.h>

#include <random>
#include <set>

using namespace view_selection::core;

namespace {

PairChanges changes(std::vector<Pair> added, std::vector<Pair> removed = {}) {
  PairChanges c;
  c.added = std::move(added);
  c.removed = std::move(removed);
  return c;
}

}  // namespace

TEST(PairAnnouncer, AnnouncesOnceStillSelectedMKeyframesLater) {
  PairAnnouncer a(2);
  EXPECT_TRUE(a.update(changes({{0, 1}}), 2).empty());  // selected at 2 keyframes
  EXPECT_TRUE(a.update(changes({{1, 2}}), 3).empty());
  const Announcement at4 = a.update(changes({}), 4);  // 2 keyframes later
  EXPECT_EQ(at4.added, (std::vector<Pair>{{0, 1}}));
  EXPECT_EQ(a.pending(), 1u);
  EXPECT_EQ(a.update(changes({}), 5).added, (std::vector<Pair>{{1, 2}}));
  EXPECT_EQ(a.announced(), (std::set<Pair>{{0, 1}, {1, 2}}));
}

TEST(PairAnnouncer, APairThatGoesBeforeItIsStableIsNeverAnnounced) {
  PairAnnouncer a(3);
  a.update(changes({{0, 1}, {0, 2}}), 3);
  const Announcement gone = a.update(changes({}, {{0, 2}}), 4);
  EXPECT_TRUE(gone.empty()) << "a pending pair that goes is not taken back: it was never announced";
  EXPECT_EQ(a.update(changes({}), 6).added, (std::vector<Pair>{{0, 1}}));
  // Announced, then gone: taken back.
  EXPECT_EQ(a.update(changes({}, {{0, 1}}), 7).removed, (std::vector<Pair>{{0, 1}}));
  EXPECT_TRUE(a.announced().empty());
}

TEST(PairAnnouncer, AtOnceFlushAndClear) {
  PairAnnouncer now(0);
  EXPECT_EQ(now.update(changes({{3, 4}}), 5).added, (std::vector<Pair>{{3, 4}}));
  PairAnnouncer later(5);
  later.update(changes({{1, 3}, {0, 2}}), 5);
  EXPECT_EQ(later.flush().added, (std::vector<Pair>{{0, 2}, {1, 3}}));
  EXPECT_EQ(later.pending(), 0u);
  EXPECT_TRUE(later.flush().empty());
  later.clear();
  EXPECT_TRUE(later.announced().empty());
  later.announceAll({{0, 1}, {2, 5}});
  EXPECT_EQ(later.announced(), (std::set<Pair>{{0, 1}, {2, 5}}));
  EXPECT_EQ(later.update(changes({}, {{2, 5}}), 9).removed, (std::vector<Pair>{{2, 5}}));
}

TEST(PairAnnouncer, AConsumerEndsWithTheFinalSelectionWhateverTheChurn) {
  // Random selections evolving keyframe by keyframe; a consumer applying every announcement
  // holds, after the final flush, exactly the last selection, for every m.
  std::mt19937 rng(7);
  for (int m : {0, 1, 3, 8}) {
    PairAnnouncer a(m);
    std::set<Pair> selected, consumer;
    std::size_t wasted_added = 0;
    for (std::size_t n = 2; n < 200; ++n) {
      std::set<Pair> next;
      for (const Pair& p : selected)
        if (rng() % 4 != 0) next.insert(p);
      for (int q = 0; q < 4; ++q) {
        const ViewId j = static_cast<ViewId>(n - 1), i = static_cast<ViewId>(rng() % (n - 1));
        next.insert({i, j});
      }
      PairChanges c;
      for (const Pair& p : next)
        if (!selected.count(p)) c.added.push_back(p);
      for (const Pair& p : selected)
        if (!next.count(p)) c.removed.push_back(p);
      selected = next;
      const Announcement out = a.update(c, n);
      for (const Pair& p : out.removed) {
        ASSERT_TRUE(consumer.erase(p)) << "took back a pair never announced";
        ++wasted_added;
      }
      for (const Pair& p : out.added) ASSERT_TRUE(consumer.insert(p).second) << "announced twice";
    }
    for (const Pair& p : a.flush().added) consumer.insert(p);
    EXPECT_EQ(consumer, selected) << "m " << m;
    EXPECT_EQ(a.announced(), selected);
  }
}
