#include "view_selection/core/selection_cache.h"

#include "view_selection/core/error_resistance.h"

#include "selection_steps.h"

#include <algorithm>
#include <cmath>

namespace view_selection::core {

using detail::bestPredecessor;
using detail::better;

void SelectionCache::clear() {
  // The pairs that go with the old selection, for whoever follows the changes.
  if (track_pair_changes_)
    for (const auto& [a, b] : selection_.pairs) logPair(a, b, false);
  configured_ = false;
  selection_ = ChunkedSelection{};
  counted_.clear();
  final_changed_.clear();
  final_changed_flag_.clear();
  seen_.clear();
  first_value_.clear();
  extended_rows_.clear();
  extended_.clear();
  flat_.clear();
  flat_size_.clear();
  changed_.clear();
  previous_size_ = 0;
  previous_start_ = -1;
  resumable_ = false;
  position_.clear();
  parent_.clear();
  plain_length_ = 0;
}

void SelectionCache::findChangedRows(const ErrorResistanceTable& e) {
  const size_t n = e.size();
  seen_.resize(n, 0);
  first_value_.resize(n, kInfinity);
  changed_.clear();
  for (size_t i = 0; i < n; ++i) {
    const std::uint64_t version = e.rowVersion(static_cast<ViewId>(i));
    // A row never set (version 0) is empty and stays so until it gets a version.
    if (i < previous_size_ && seen_[i] == version) continue;
    seen_[i] = version;
    changed_.push_back(static_cast<ViewId>(i));
    const auto& top = e.top(static_cast<ViewId>(i));
    first_value_[i] = config_.k >= 1 && !top.empty() ? top.front().value : kInfinity;
  }
}

void SelectionCache::resetFinalSets() {
  auto& final_sets = selection_.final_next_views;
  for (const ViewId a : extended_rows_)
    if (static_cast<size_t>(a) < final_sets.size()) {
      final_sets.set(static_cast<size_t>(a), selection_.next_views[static_cast<size_t>(a)]);
      extended_[static_cast<size_t>(a)] = 0;
      finalSetChanged(a);
    }
  extended_rows_.clear();
}

void SelectionCache::refreshSets(const ErrorResistanceTable& e) {
  const size_t n = e.size();
  auto& next = selection_.next_views;
  auto& final_sets = selection_.final_next_views;
  next.resize(n);
  final_sets.resize(n);
  extended_.resize(n, 0);
  const size_t keep = static_cast<size_t>(config_.k);
  // A flat copy of the sets (stride k) for the traversal: contiguous, where the sets themselves
  // are one small allocation each. Only for k within the table's cached best entries.
  flat_stride_ = keep <= ErrorResistanceTable::kTopCapacity ? keep : 0;
  flat_size_.resize(n, 0);
  flat_.resize(n * flat_stride_);
  std::vector<TableEntry> best;
  final_changed_flag_.resize(n, 0);
  for (const ViewId row : changed_) {
    const auto i = static_cast<size_t>(row);
    auto& set = next.edit(i);
    set.clear();
    if (keep <= ErrorResistanceTable::kTopCapacity) {
      const auto& top = e.top(row);
      const size_t take = std::min(keep, top.size());
      for (size_t q = 0; q < take; ++q) set.push_back(top[q].view);
    } else {
      best.assign(e.row(row).begin(), e.row(row).end());
      const size_t take = std::min(keep, best.size());
      std::partial_sort(best.begin(), best.begin() + static_cast<std::ptrdiff_t>(take), best.end(),
                        [](const TableEntry& a, const TableEntry& b) {
                          return better(a.value, a.view, b.value, b.view);
                        });
      for (size_t q = 0; q < take; ++q) set.push_back(best[q].view);
    }
    // A changed row holds no completion that is kept: a kept completion's view was added to a
    // view visited before the first changed row's position.
    final_sets.set(i, set);
    extended_[i] = 0;
    finalSetChanged(row);
    if (flat_stride_) {
      std::copy(set.begin(), set.end(), flat_.begin() + static_cast<std::ptrdiff_t>(i * flat_stride_));
      flat_size_[i] = static_cast<std::uint32_t>(set.size());
    }
  }
}

SetView SelectionCache::plainSet(ViewId i) const {
  if (flat_stride_)
    return {flat_.data() + static_cast<size_t>(i) * flat_stride_, flat_size_[static_cast<size_t>(i)]};
  const NextViewSet& c = selection_.next_views[static_cast<size_t>(i)];
  return {c.data(), c.size()};
}

SetView SelectionCache::finalSet(ViewId i) const {
  if (extended_[static_cast<size_t>(i)] || !flat_stride_) {
    const NextViewSet& c = selection_.final_next_views[static_cast<size_t>(i)];
    return {c.data(), c.size()};
  }
  return plainSet(i);
}

void SelectionCache::visit(ViewId v, ViewId parent) {
  visited_[static_cast<size_t>(v)] = 1;
  position_[static_cast<size_t>(v)] = static_cast<std::int32_t>(selection_.order.size());
  parent_[static_cast<size_t>(v)] = parent;
  selection_.order.push_back(v);
}

template <typename Sets>
void SelectionCache::traverseFrom(const Sets& sets) {
  // traverseSets' loop, recording where each view was reached from.
  while (!stack_.empty()) {
    auto& [current, cursor] = stack_.back();
    const SetView candidates = sets(current);
    while (cursor < candidates.size && visited_[static_cast<size_t>(candidates.data[cursor])]) ++cursor;
    if (cursor == candidates.size) {
      stack_.pop_back();
      continue;
    }
    const ViewId next = candidates.data[cursor];
    const ViewId from = current;  // before emplace_back moves the frames
    visit(next, from);
    stack_.emplace_back(next, 0);
  }
}

void SelectionCache::completePaper(const ErrorResistanceTable& e) {
  // The definition's own paper completion (it traverses nothing), then the rows it lengthened.
  detail::completePaper(e, visited_, selection_);
  for (const CompletedView& c : selection_.completed) {
    extended_rows_.push_back(c.added_to);
    extended_[static_cast<size_t>(c.added_to)] = 1;
    finalSetChanged(c.added_to);
  }
}

void SelectionCache::offer(ViewId x) {
  if (visited_[static_cast<size_t>(x)] || queued_[static_cast<size_t>(x)]) return;
  queued_[static_cast<size_t>(x)] = 1;
  candidates_.push(x);
}

void SelectionCache::offerIfReached(const ErrorResistanceTable& e, ViewId x) {
  if (visited_[static_cast<size_t>(x)]) return;
  for (const TableEntry& entry : e.column(x))
    if (visited_[static_cast<size_t>(entry.view)]) return offer(x);
}

void SelectionCache::completeReachable(const ErrorResistanceTable& e) {
  // The same candidates as the plain definition (unvisited views with a finite entry from a
  // visited one), found from the unvisited side: a column of each view the traversal missed.
  // A min-heap with a flag per view instead of a set: each view enters at most once, since a
  // candidate stays a candidate until completion visits it.
  candidates_ = {};
  queued_.assign(e.size(), 0);
  for (size_t x = 0; x < e.size(); ++x) offerIfReached(e, static_cast<ViewId>(x));
  completionLoop(e);
}

void SelectionCache::completionLoop(const ErrorResistanceTable& e) {
  ChunkedSelection& out = selection_;
  while (!candidates_.empty()) {
    const ViewId x = candidates_.top();
    candidates_.pop();
    if (visited_[static_cast<size_t>(x)]) continue;
    const ViewId a = bestPredecessor(e, x, &visited_);
    out.final_next_views.edit(static_cast<size_t>(a)).push_back(x);
    extended_rows_.push_back(a);
    extended_[static_cast<size_t>(a)] = 1;
    finalSetChanged(a);
    out.completed.push_back({x, a});
    const size_t scanned = out.order.size();
    visit(x, -1);
    stack_.assign(1, {x, 0});
    traverseFrom([this](ViewId i) { return finalSet(i); });
    for (size_t q = scanned; q < out.order.size(); ++q)
      for (const TableEntry& entry : e.row(out.order[q])) offer(entry.view);
  }
  out.isolated.clear();
  for (size_t x = 0; x < e.size(); ++x)
    if (!visited_[x]) out.isolated.push_back(static_cast<ViewId>(x));
}

std::ptrdiff_t SelectionCache::resumePosition(ViewId start) const {
  if (!resumable_ || config_.completion != CompletionMode::kReachable || start < 0 ||
      start != previous_start_)
    return -1;
  // Up to the first position whose view's row changed, the traversal and completion read only
  // unchanged rows (sets, candidates and predecessors all come from the visited views' rows).
  size_t p = selection_.order.size();
  for (const ViewId i : changed_)
    if (static_cast<size_t>(i) < previous_size_ && position_[static_cast<size_t>(i)] >= 0)
      p = std::min(p, static_cast<size_t>(position_[static_cast<size_t>(i)]));
  if (p == 0) return -1;  // s's own set changed: everything is redone
  return static_cast<std::ptrdiff_t>(p);
}

void SelectionCache::undoCompletionsFrom(size_t p) {
  ChunkedSelection& out = selection_;
  size_t keep = out.completed.size();
  while (keep > 0 &&
         static_cast<size_t>(position_[static_cast<size_t>(out.completed[keep - 1].view)]) >= p) {
    --keep;
    const auto a = static_cast<size_t>(out.completed[keep].added_to);
    out.final_next_views.edit(a).pop_back();
    if (out.final_next_views[a].size() == out.next_views[a].size()) extended_[a] = 0;
    finalSetChanged(out.completed[keep].added_to);
  }
  out.completed.resize(keep);
  extended_rows_.clear();
  for (const CompletedView& c : out.completed) extended_rows_.push_back(c.added_to);
}

void SelectionCache::resumeReachable(const ErrorResistanceTable& e, size_t p) {
  ChunkedSelection& out = selection_;
  const size_t n = e.size();
  // The views to look at again: the old order from p on, the isolated, the new.
  reexamine_.assign(out.order.begin() + static_cast<std::ptrdiff_t>(p), out.order.end());
  reexamine_.insert(reexamine_.end(), out.isolated.begin(), out.isolated.end());
  for (size_t v = previous_size_; v < n; ++v) reexamine_.push_back(static_cast<ViewId>(v));
  // Inside a traversal (from s, or a completion's): its depth-first stack when it reached
  // order[p], rebuilt from the parents (each ancestor's cursor at the child on the path; any
  // cursor before it would do, since what it skipped is still visited).
  stack_.clear();
  if (p < out.order.size() && parent_[static_cast<size_t>(out.order[p])] >= 0) {
    std::vector<ViewId> path{out.order[p]};
    while (parent_[static_cast<size_t>(path.back())] >= 0)
      path.push_back(parent_[static_cast<size_t>(path.back())]);
    for (size_t q = path.size() - 1; q >= 1; --q) {
      const ViewId a = path[q], child = path[q - 1];
      const SetView set = finalSet(a);
      const auto at = std::find(set.data, set.data + set.size, child);
      stack_.emplace_back(a, static_cast<size_t>(at - set.data));
    }
  }
  for (size_t q = p; q < out.order.size(); ++q) {
    visited_[static_cast<size_t>(out.order[q])] = 0;
    position_[static_cast<size_t>(out.order[q])] = -1;
  }
  out.order.resize(p);
  visited_.resize(n, 0);
  position_.resize(n, -1);
  parent_.resize(n, -1);
  queued_.resize(n, 0);
  // (Within the traversal from s every completion is undone, so the final sets are the plain
  // ones there.)
  const bool from_s = p < plain_length_;
  if (!stack_.empty()) {
    ++resumed_inside_;
    traverseFrom([this](ViewId i) { return finalSet(i); });
  }
  if (from_s) plain_length_ = out.order.size();
  // Candidates now: the unvisited views with a finite entry from a visited one. Every view not
  // looked at again is visited.
  candidates_ = {};
  for (const ViewId x : reexamine_) queued_[static_cast<size_t>(x)] = 0;
  for (const ViewId x : reexamine_) offerIfReached(e, x);
  completionLoop(e);
}

void SelectionCache::finalSetChanged(ViewId a) {
  const auto i = static_cast<size_t>(a);
  if (final_changed_flag_.size() <= i) final_changed_flag_.resize(i + 1, 0);
  if (final_changed_flag_[i]) return;
  final_changed_flag_[i] = 1;
  final_changed_.push_back(a);
}

void SelectionCache::logPair(ViewId a, ViewId b, bool added) {
  pair_log_.push_back({std::min(a, b), std::max(a, b), added});
}

void SelectionCache::updatePairs() {
  const auto& final_sets = selection_.final_next_views;
  const size_t n = final_sets.size();
  selection_.pairs.resize(n);
  static const NextViewSet kEmpty;
  auto holds = [](const NextViewSet& set, ViewId x) {
    return std::find(set.begin(), set.end(), x) != set.end();
  };
  for (const ViewId a : final_changed_) {
    const auto i = static_cast<size_t>(a);
    final_changed_flag_[i] = 0;
    const NextViewSet& was = i < counted_.size() ? counted_[i] : kEmpty;
    const NextViewSet& now = final_sets[i];
    if (was == now) continue;
    for (const ViewId x : was)
      if (!holds(now, x) && selection_.pairs.remove(a, x) && track_pair_changes_)
        logPair(a, x, false);
    for (const ViewId x : now)
      if (!holds(was, x) && selection_.pairs.add(a, x) && track_pair_changes_) logPair(a, x, true);
  }
  final_changed_.clear();
  counted_ = final_sets;  // a copy sharing every chunk
}

void SelectionCache::trackPairChanges(bool on) {
  track_pair_changes_ = on;
  if (!on) pair_log_.clear();
}

PairChanges SelectionCache::takePairChanges() {
  PairChanges out;
  // Per pair, in the order they happened: the first event says whether it was there before,
  // the last whether it is there now.
  std::stable_sort(pair_log_.begin(), pair_log_.end(), [](const PairEvent& x, const PairEvent& y) {
    return x.lo < y.lo || (x.lo == y.lo && x.hi < y.hi);
  });
  for (size_t q = 0; q < pair_log_.size();) {
    size_t end = q;
    while (end < pair_log_.size() && pair_log_[end].lo == pair_log_[q].lo &&
           pair_log_[end].hi == pair_log_[q].hi)
      ++end;
    const bool before = !pair_log_[q].added, after = pair_log_[end - 1].added;
    if (!before && after) out.added.emplace_back(pair_log_[q].lo, pair_log_[q].hi);
    if (before && !after) out.removed.emplace_back(pair_log_[q].lo, pair_log_[q].hi);
    q = end;
  }
  pair_log_.clear();
  return out;
}

const ChunkedSelection& SelectionCache::update(const ErrorResistanceTable& e,
                                        const SelectionConfig& config) {
  config.validate();
  if (!configured_ || config.k != config_.k || config.completion != config_.completion ||
      e.size() < previous_size_)
    clear();
  config_ = config;
  configured_ = true;
  ++updates_;
  ChunkedSelection& out = selection_;
  const size_t n = e.size();
  findChangedRows(e);
  // s: the best C_i[0] by (value, row); rows ascend, so a tie keeps the smaller row.
  ViewId start = -1;
  double best_value = kInfinity;
  for (size_t i = 0; i < n; ++i)
    if (first_value_[i] < best_value) {
      best_value = first_value_[i];
      start = static_cast<ViewId>(i);
    }
  const std::ptrdiff_t resume = resumePosition(start);
  if (resume >= 0) {
    undoCompletionsFrom(static_cast<size_t>(resume));  // before the changed rows' sets change
    refreshSets(e);
    out.start_view = start;
    resumeReachable(e, static_cast<size_t>(resume));
    ++resumed_updates_;
  } else {
    resetFinalSets();
    refreshSets(e);
    out.start_view = start;
    visited_.assign(n, 0);
    position_.assign(n, -1);
    parent_.assign(n, -1);
    out.order.clear();
    out.completed.clear();
    out.isolated.clear();
    stack_.clear();
    if (start >= 0) {
      visit(start, -1);
      stack_.assign(1, {start, 0});
      traverseFrom([this](ViewId i) { return plainSet(i); });
    }
    plain_length_ = out.order.size();
    if (config_.completion == CompletionMode::kPaper)
      completePaper(e);
    else
      completeReachable(e);
  }
  previous_size_ = n;
  previous_start_ = start;
  resumable_ = config_.completion == CompletionMode::kReachable && start >= 0;
  updatePairs();
  return out;
}

}  // namespace view_selection::core
