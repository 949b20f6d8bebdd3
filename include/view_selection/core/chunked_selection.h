// A Selection with every per-view list chunked and shared between copies: what SelectionCache
// keeps and what the node's readers share.
#pragma once

#include "view_selection/core/chunked_vector.h"
#include "view_selection/core/pair_buckets.h"
#include "view_selection/core/selection.h"
#include "view_selection/core/types.h"

#include <utility>

namespace view_selection::core {

/// A Selection as SelectionCache keeps it and the node's outputs read it: the same fields, with
/// every per-view list chunked and shared between copies (ChunkedVector, PairBuckets), so that
/// a copy for readers costs O(n / 256) and not O(n).
struct ChunkedSelection {
  ChunkedVector<NextViewSet> next_views;        ///< C_i before completion
  ChunkedVector<NextViewSet> final_next_views;  ///< C_i after completion
  ViewId start_view = -1;
  ChunkedVector<ViewId> order;
  ChunkedVector<CompletedView> completed;
  ChunkedVector<ViewId> isolated;
  PairBuckets pairs;

  std::pair<ViewId, ViewId> initialPair() const;
  /// The plain Selection with the same content, O(n).
  Selection toSelection() const;
  /// The chunked form of a plain Selection (each pair counted once), O(n).
  static ChunkedSelection of(const Selection& plain);
};

}  // namespace view_selection::core
