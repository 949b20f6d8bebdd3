#include "view_selection/core/error_resistance_table.h"

#include "view_selection/core/error_resistance.h"
#include "view_selection/core/exceptions.h"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <string>

namespace view_selection::core {

namespace {
bool byView(const TableEntry& e, ViewId v) { return e.view < v; }
/// METHOD.md's order of candidates: by value, then by id.
bool byValue(const TableEntry& a, const TableEntry& b) {
  return a.value < b.value || (a.value == b.value && a.view < b.view);
}
}  // namespace

ErrorResistanceTable ErrorResistanceTable::fromDense(
    const std::vector<std::vector<double>>& dense) {
  ErrorResistanceTable table(dense.size());
  for (size_t i = 0; i < dense.size(); ++i) {
    if (dense[i].size() != dense.size())
      throw InvalidArgument("error-resistance matrix is not square: row " + std::to_string(i) +
                            " has " + std::to_string(dense[i].size()) + " entries, expected " +
                            std::to_string(dense.size()));
    for (size_t j = 0; j < dense.size(); ++j)
      table.set(static_cast<ViewId>(i), static_cast<ViewId>(j), dense[i][j]);
  }
  return table;
}

void ErrorResistanceTable::resize(size_t size) {
  if (size < rows_.size()) throw InvalidArgument("ErrorResistanceTable::resize cannot shrink");
  rows_.resize(size);
  cols_.resize(size);
  top_.resize(size);
  row_version_.resize(size, 0);
}

namespace {
std::atomic<std::uint64_t> next_row_version{1};
}  // namespace

std::uint64_t ErrorResistanceTable::lastVersionIssued() {
  return next_row_version.load(std::memory_order_relaxed) - 1;
}

void ErrorResistanceTable::touch(size_t i) {
  const std::uint64_t version = next_row_version.fetch_add(1, std::memory_order_relaxed);
  row_version_.edit(i) = version;
  const size_t chunk = i / kVersionChunk;
  if (chunk >= chunk_version_.size()) chunk_version_.resize(chunk + 1, 0);
  chunk_version_[chunk] = version;  // versions only grow: the chunk's largest
}

void ErrorResistanceTable::clear() {
  rows_.clear();
  cols_.clear();
  top_.clear();
  row_version_.clear();
  chunk_version_.clear();
  finite_count_ = 0;
}

double ErrorResistanceTable::at(ViewId i, ViewId j) const {
  const auto& row = rows_.at(static_cast<size_t>(i)).get();
  const auto it = std::lower_bound(row.begin(), row.end(), j, byView);
  return (it != row.end() && it->view == j) ? it->value : kInfinity;
}

void ErrorResistanceTable::upsert(std::vector<TableEntry>& list, ViewId view, double value) {
  // Entries usually arrive with the largest id so far (a new keyframe): append fast path.
  if (list.empty() || list.back().view < view) {
    list.push_back({view, value});
    return;
  }
  const auto it = std::lower_bound(list.begin(), list.end(), view, byView);
  if (it != list.end() && it->view == view)
    it->value = value;
  else
    list.insert(it, {view, value});
}

bool ErrorResistanceTable::erase(std::vector<TableEntry>& list, ViewId view) {
  const auto it = std::lower_bound(list.begin(), list.end(), view, byView);
  if (it == list.end() || it->view != view) return false;
  list.erase(it);
  return true;
}

void ErrorResistanceTable::set(ViewId i, ViewId j, double value) {
  if (i < 0 || j < 0 || static_cast<size_t>(i) >= size() || static_cast<size_t>(j) >= size())
    throw InvalidArgument("ErrorResistanceTable::set: index out of range");
  if (i == j) return;
  const auto ui = static_cast<size_t>(i), uj = static_cast<size_t>(j);
  if (std::isfinite(value)) {
    const size_t before = rows_[ui].get().size();
    upsert(editRow(ui), j, value);
    upsert(editColumn(uj), i, value);
    finite_count_ += rows_[ui].get().size() - before;
    updateTop(static_cast<size_t>(i), j, value);
    touch(static_cast<size_t>(i));
    return;
  }
  // Removing an entry that is not there changes nothing and copies nothing.
  const auto& current = rows_[ui].get();
  const auto it = std::lower_bound(current.begin(), current.end(), j, byView);
  if (it == current.end() || it->view != j) return;
  erase(editRow(ui), j);
  erase(editColumn(uj), i);
  --finite_count_;
  updateTop(static_cast<size_t>(i), j, kInfinity);
  touch(static_cast<size_t>(i));
}

void ErrorResistanceTable::updateTop(size_t i, ViewId j, double value) {
  // Read first, edit (and so copy a shared list) only when the top changes.
  const auto& view = top_[i].get();
  const size_t row_size = rows_[i].get().size();
  const auto found =
      std::find_if(view.begin(), view.end(), [j](const TableEntry& e) { return e.view == j; });
  if (found != view.end()) {
    const auto at = found - view.begin();
    // An entry of the top changed: if it got better (or as good), it stays; otherwise an entry
    // outside the top may now belong in it, which only a scan of the row can tell.
    if (std::isfinite(value) && (!byValue({j, found->value}, {j, value}) || row_size <= view.size())) {
      // (or the whole row is in the top: just reorder)
      auto& top = editTop(i);
      top[static_cast<size_t>(at)].value = value;
      std::sort(top.begin(), top.end(), byValue);
      return;
    }
    rescanTop(i);
    return;
  }
  if (!std::isfinite(value)) return;  // removed an entry outside the top: nothing changes
  const TableEntry entry{j, value};
  if (view.size() < kTopCapacity) {
    // The top held the whole row before this entry arrived.
    auto& top = editTop(i);
    top.insert(std::upper_bound(top.begin(), top.end(), entry, byValue), entry);
    return;
  }
  if (byValue(entry, view.back())) {
    auto& top = editTop(i);
    top.pop_back();
    top.insert(std::upper_bound(top.begin(), top.end(), entry, byValue), entry);
  }
}

void ErrorResistanceTable::rescanTop(size_t i) {
  const auto& row = rows_[i].get();
  auto& top = editTop(i);
  top.assign(row.begin(), row.end());
  const size_t keep = std::min(kTopCapacity, top.size());
  std::partial_sort(top.begin(), top.begin() + static_cast<std::ptrdiff_t>(keep), top.end(),
                    byValue);
  top.resize(keep);
}

void ErrorResistanceTable::replaceRow(ViewId i, std::vector<TableEntry> entries) {
  if (i < 0 || static_cast<size_t>(i) >= size())
    throw InvalidArgument("ErrorResistanceTable::replaceRow: row out of range");
  for (const TableEntry& e : entries)
    if (e.view < 0 || static_cast<size_t>(e.view) >= size())
      throw InvalidArgument("ErrorResistanceTable::replaceRow: column out of range");
  auto& row = editRow(static_cast<size_t>(i));
  for (const TableEntry& e : row) erase(editColumn(static_cast<size_t>(e.view)), i);
  finite_count_ -= row.size();
  row.clear();
  std::sort(entries.begin(), entries.end(),
            [](const TableEntry& a, const TableEntry& b) { return a.view < b.view; });
  for (const TableEntry& e : entries) {
    if (e.view == i || !std::isfinite(e.value)) continue;
    row.push_back(e);
    upsert(editColumn(static_cast<size_t>(e.view)), i, e.value);
  }
  finite_count_ += row.size();
  rescanTop(static_cast<size_t>(i));
  touch(static_cast<size_t>(i));
}

std::vector<std::vector<double>> ErrorResistanceTable::dense() const {
  std::vector<std::vector<double>> out(size(), std::vector<double>(size(), kInfinity));
  for (size_t i = 0; i < size(); ++i)
    for (const TableEntry& e : rows_[i].get()) out[i][static_cast<size_t>(e.view)] = e.value;
  return out;
}

}  // namespace view_selection::core
