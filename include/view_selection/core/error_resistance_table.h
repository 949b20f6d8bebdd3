// Sparse storage of the error-resistance matrix E: only finite entries are kept, by row and by
// column. A missing entry is +inf (no co-visibility, a gate, or the diagonal). Views that see
// nothing in common are the norm on long sequences, so selection runs in O(finite entries).
#pragma once

#include "view_selection/core/chunked_vector.h"
#include "view_selection/core/types.h"

#include <cstddef>
#include <cstdint>
#include <memory>
#include <vector>

namespace view_selection::core {

/// One finite entry of a row (view = column index) or of a column (view = row index).
struct TableEntry {
  ViewId view;
  double value;
  bool operator==(const TableEntry& o) const { return view == o.view && value == o.value; }
};

/// A list of entries shared between copies of a table until one of them changes it (copy on
/// write): copying a table, as every output does, costs a pointer a chunk of lists
/// (ChunkedVector), not the entries. A list is changed in place only by the table whose sharing
/// epoch made it (chunked_vector.h says why epochs and not reference counts).
class SharedEntries {
 public:
  const std::vector<TableEntry>& get() const { return list_ ? *list_ : empty(); }
  /// The list to change, copied first when it was made under another epoch than `epoch` (the
  /// table's now), i.e. another table may still read it.
  std::vector<TableEntry>& edit(std::uint64_t epoch) {
    if (!list_) {
      list_ = std::make_shared<std::vector<TableEntry>>();
    } else if (epoch_ != epoch) {
      list_ = std::make_shared<std::vector<TableEntry>>(*list_);
    }
    epoch_ = epoch;
    return *list_;
  }
  bool operator==(const SharedEntries& o) const { return get() == o.get(); }

 private:
  static const std::vector<TableEntry>& empty() {
    static const std::vector<TableEntry> none;
    return none;
  }
  std::shared_ptr<std::vector<TableEntry>> list_;
  std::uint64_t epoch_ = 0;
};

class ErrorResistanceTable {
 public:
  explicit ErrorResistanceTable(size_t size = 0) { resize(size); }

  /// From a dense square matrix; non-finite entries and the diagonal are left out.
  static ErrorResistanceTable fromDense(const std::vector<std::vector<double>>& dense);

  size_t size() const { return rows_.size(); }
  /// Grows to `size` views (never shrinks; use clear()).
  void resize(size_t size);
  void clear();

  /// E[i][j]; +inf when absent.
  double at(ViewId i, ViewId j) const;
  /// Sets E[i][j]; a non-finite value removes the entry. i == j is ignored (the diagonal is +inf).
  void set(ViewId i, ViewId j, double value);
  /// Replaces row i with `entries` (any order, finite values, no diagonal).
  void replaceRow(ViewId i, std::vector<TableEntry> entries);

  /// Finite entries of row i, ascending by column.
  const std::vector<TableEntry>& row(ViewId i) const { return rows_[static_cast<size_t>(i)].get(); }
  /// Finite entries of column j, ascending by row.
  const std::vector<TableEntry>& column(ViewId j) const { return cols_[static_cast<size_t>(j)].get(); }

  size_t finiteCount() const { return finite_count_; }

  /// The best min(kTopCapacity, |row i|) entries of row i, ascending by (value, view): kept up
  /// to date on every change, so next view sets with k <= kTopCapacity cost O(k) a row.
  static constexpr size_t kTopCapacity = 16;
  const std::vector<TableEntry>& top(ViewId i) const { return top_[static_cast<size_t>(i)].get(); }
  /// Changes whenever row i changes, to a value no other row of any table ever had: equal
  /// versions mean equal rows, also across copies (SelectionCache keys on it). 0: never set.
  std::uint64_t rowVersion(ViewId i) const { return row_version_[static_cast<size_t>(i)]; }
  /// The largest row version of rows [c * kVersionChunk, (c + 1) * kVersionChunk) (0: none set),
  /// so that finding the rows changed since a moment costs O(n / kVersionChunk) plus theirs.
  static constexpr size_t kVersionChunk = 256;
  std::uint64_t chunkVersion(size_t c) const {
    return c < chunk_version_.size() ? chunk_version_[c] : 0;
  }
  /// The last version any row of any table got: rows changed later get larger ones.
  static std::uint64_t lastVersionIssued();
  /// Dense copy, +inf for absent entries.
  std::vector<std::vector<double>> dense() const;

  bool operator==(const ErrorResistanceTable& o) const { return rows_ == o.rows_; }
  bool operator!=(const ErrorResistanceTable& o) const { return !(*this == o); }

 private:
  static void upsert(std::vector<TableEntry>& list, ViewId view, double value);
  static bool erase(std::vector<TableEntry>& list, ViewId view);
  /// Keeps top_[i] right after E[i][j] became `value` (+inf: removed).
  void updateTop(size_t i, ViewId j, double value);
  void rescanTop(size_t i);

  std::vector<TableEntry>& editRow(size_t i) { return rows_.edit(i).edit(epoch_.get()); }
  std::vector<TableEntry>& editColumn(size_t j) { return cols_.edit(j).edit(epoch_.get()); }
  std::vector<TableEntry>& editTop(size_t i) { return top_.edit(i).edit(epoch_.get()); }
  void touch(size_t i);

  ChunkedVector<SharedEntries> rows_;
  ChunkedVector<SharedEntries> cols_;
  ChunkedVector<SharedEntries> top_;
  ChunkedVector<std::uint64_t> row_version_;
  std::vector<std::uint64_t> chunk_version_;  // by kVersionChunk rows
  size_t finite_count_ = 0;
  SharingEpoch epoch_;  ///< which lists this table may change in place
};

}  // namespace view_selection::core
