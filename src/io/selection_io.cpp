#include "view_selection/io/selection_io.h"

#include "view_selection/core/error_resistance.h"
#include "view_selection/core/exceptions.h"

#include <cmath>
#include "view_selection/io/atomic_file.h"

#include <fstream>
#include <sstream>

namespace view_selection::io {

namespace {

nlohmann::json finiteOrNull(double value) {
  return std::isfinite(value) ? nlohmann::json(value) : nlohmann::json(nullptr);
}

nlohmann::json keyframeToJson(core::ViewId id, const core::KeyframeSummary& kf,
                              const std::string& image, const Eigen::Matrix3Xd* points) {
  const Eigen::Quaterniond q = kf.pose.orientation.normalized();
  const core::PinholeIntrinsics& k = kf.intrinsics;
  nlohmann::json j = {
      {"id", id},
      {"stamp", kf.stamp},
      {"image", image},
      {"position", {kf.pose.position.x(), kf.pose.position.y(), kf.pose.position.z()}},
      {"orientation_xyzw", {q.x(), q.y(), q.z(), q.w()}},
      {"intrinsics", {k.fx, k.fy, k.cx, k.cy, k.width, k.height}},
      {"num_points", kf.num_points},
  };
  if (kf.revisit_of >= 0) j["revisit_of"] = kf.revisit_of;
  if (points) {
    nlohmann::json list = nlohmann::json::array();
    for (Eigen::Index c = 0; c < points->cols(); ++c)
      list.push_back({(*points)(0, c), (*points)(1, c), (*points)(2, c)});
    j["points"] = std::move(list);
  }
  return j;
}

}  // namespace

namespace {

/// Writes selection.json to `out` element by element, never holding the document: METHOD.md's keys
/// in METHOD.md's order, one line per element of the long arrays (keyframes, matrix rows, sets).
class SelectionWriter {
 public:
  SelectionWriter(std::ostream& out) : out_(out) {}

  void write(const core::SelectionOutput& snapshot, const nlohmann::json& params,
             const core::ErrorResistanceMatrix* points, bool sparse) {
    const size_t n = snapshot.size();
    const core::ChunkedSelection& sel = snapshot.selection;
    out_ << "{\n";
    key("format");
    out_ << nlohmann::json(sparse ? kSparseFormat : kDenseFormat).dump();
    key("params");
    out_ << params.dump();
    key("keyframes");
    list(n, [&](size_t i) {
      const auto id = static_cast<core::ViewId>(i);
      out_ << keyframeToJson(id, snapshot.keyframes[i], snapshot.imageName(i),
                             points ? &points->keyframe(id).points : nullptr)
                  .dump();
    });
    key("error_resistance");
    list(n, [&](size_t i) {
      const auto& row = snapshot.table.row(static_cast<core::ViewId>(i));
      out_ << '[';
      if (sparse) {
        for (size_t q = 0; q < row.size(); ++q)
          out_ << (q ? "," : "") << '[' << row[q].view << ',' << number(row[q].value) << ']';
      } else {
        size_t next = 0;  // row entries ascend by column
        for (size_t j = 0; j < n; ++j) {
          if (j) out_ << ',';
          if (next < row.size() && static_cast<size_t>(row[next].view) == j)
            out_ << number(row[next++].value);
          else
            out_ << "null";
        }
      }
      out_ << ']';
    });
    key("next_views");
    sets(sel.next_views);
    key("start_view");
    out_ << (sel.start_view >= 0 ? std::to_string(sel.start_view) : "null");
    key("initial_pair");
    const auto [s, s_first] = sel.initialPair();
    out_ << (s >= 0 ? "[" + std::to_string(s) + "," + std::to_string(s_first) + "]" : "null");
    key("order");
    ids(sel.order);
    key("completed");
    list(sel.completed.size(), [&](size_t q) {
      out_ << "{\"added_to\":" << sel.completed[q].added_to << ",\"view\":" << sel.completed[q].view << '}';
    });
    key("isolated");
    ids(sel.isolated);
    key("final_next_views");
    sets(sel.final_next_views);
    key("pairs");
    auto pair = sel.pairs.begin();
    list(sel.pairs.size(), [&](size_t) {
      const auto [a, b] = *pair;
      out_ << '[' << a << ',' << b << ']';
      ++pair;
    });
    out_ << "\n}\n";
  }

 private:
  void key(const char* name) {
    out_ << (first_ ? "" : ",\n") << "  \"" << name << "\": ";
    first_ = false;
  }
  /// A non-empty array one element a line; an empty one as [].
  template <typename F>
  void list(size_t size, F element) {
    if (size == 0) {
      out_ << "[]";
      return;
    }
    out_ << "[\n";
    for (size_t q = 0; q < size; ++q) {
      out_ << "    ";
      element(q);
      out_ << (q + 1 < size ? ",\n" : "\n");
    }
    out_ << "  ]";
  }
  template <typename Ids>
  void ids(const Ids& values) {
    out_ << '[';
    for (size_t q = 0; q < values.size(); ++q) out_ << (q ? "," : "") << values[q];
    out_ << ']';
  }
  void sets(const core::ChunkedVector<core::NextViewSet>& values) {
    list(values.size(), [&](size_t i) { ids(values[i]); });
  }
  /// The shortest text that reads back as the same double (nlohmann's), null for +inf.
  static std::string number(double value) { return finiteOrNull(value).dump(); }

  std::ostream& out_;
  bool first_ = true;
};

}  // namespace

bool sparseFormatFor(size_t keyframes, JsonFormat format) {
  return format == JsonFormat::kSparse ||
         (format == JsonFormat::kAuto && keyframes > kDenseFormatMaxKeyframes);
}

void writeSelectionJson(std::ostream& out, const core::SelectionOutput& snapshot,
                        const nlohmann::json& params, const core::ErrorResistanceMatrix* points,
                        JsonFormat format) {
  SelectionWriter(out).write(snapshot, params, points, sparseFormatFor(snapshot.size(), format));
}

nlohmann::json selectionToJson(const core::SelectionOutput& snapshot,
                               const nlohmann::json& params,
                               const core::ErrorResistanceMatrix* points, JsonFormat format) {
  std::stringstream text;
  writeSelectionJson(text, snapshot, params, points, format);
  return nlohmann::json::parse(text.str());
}

nlohmann::json selectionToJson(const core::ErrorResistanceMatrix& matrix,
                               const core::Selection& selection, const nlohmann::json& params,
                               bool dump_points) {
  return selectionToJson(core::makeOutput(matrix, selection, {}), params,
                         dump_points ? &matrix : nullptr);
}

void writeSelectionJson(const std::string& path, const core::SelectionOutput& snapshot,
                        const nlohmann::json& params, const core::ErrorResistanceMatrix* points,
                        JsonFormat format) {
  // Streamed to the file: the system's reason on failure (a full disk, ...).
  writeFileStreaming(path, [&](std::ostream& out) {
    writeSelectionJson(out, snapshot, params, points, format);
  });
}

void writeSelectionJson(const std::string& path, const core::ErrorResistanceMatrix& matrix,
                        const core::Selection& selection, const nlohmann::json& params,
                        bool dump_points, JsonFormat format) {
  writeSelectionJson(path, core::makeOutput(matrix, selection, {}), params,
                     dump_points ? &matrix : nullptr, format);
}

template <typename Pairs>
void writePairsTxtOf(const std::string& path, const std::vector<std::string>& image_names,
                     const Pairs& pairs) {
  for (const auto& [a, b] : pairs) {
    for (const core::ViewId v : {a, b}) {
      if (v < 0 || static_cast<size_t>(v) >= image_names.size())
        throw core::IoError("pairs.txt: view " + std::to_string(v) + " has no image name");
      const std::string& name = image_names[static_cast<size_t>(v)];
      if (name.empty() || name.find_first_of(" \t\r\n") != std::string::npos)
        throw core::IoError("pairs.txt: image name '" + name + "' of view " + std::to_string(v) +
                            " is empty or contains whitespace, which COLMAP cannot read");
    }
  }
  std::ostringstream out;
  for (const auto& [a, b] : pairs)
    out << image_names[static_cast<size_t>(a)] << ' ' << image_names[static_cast<size_t>(b)]
        << '\n';
  writeFileContents(path, out.str());
}

void writePairsTxt(const std::string& path, const std::vector<std::string>& image_names,
                   const std::vector<std::pair<core::ViewId, core::ViewId>>& pairs) {
  writePairsTxtOf(path, image_names, pairs);
}

void writePairsTxt(const std::string& path, const std::vector<std::string>& image_names,
                   const core::PairBuckets& pairs) {
  writePairsTxtOf(path, image_names, pairs);
}

void writeMvsPairTxt(const std::string& path, const core::SelectionOutput& snapshot) {
  writeFileStreaming(path, [&](std::ostream& out) {
    out.precision(9);
    const auto& sets = snapshot.selection.final_next_views;
    out << snapshot.size() << '\n';
    const std::vector<core::ViewId> none;
    for (size_t i = 0; i < snapshot.size(); ++i) {
      out << i << '\n';
      const auto& set = i < sets.size() ? sets[i] : none;
      out << set.size();
      for (const core::ViewId j : set)
        out << ' ' << j << ' ' << 1.0 / snapshot.table.at(static_cast<core::ViewId>(i), j);
      out << '\n';
    }
  });
}

nlohmann::json readSelectionJson(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw core::IoError("cannot read '" + path + "'");
  try {
    nlohmann::json doc = nlohmann::json::parse(in);
    if (!doc.is_object() || !doc.contains("format") ||
        (doc["format"] != kDenseFormat && doc["format"] != kSparseFormat))
      throw core::IoError("'" + path + "' is not a view_selection/1 or /2 selection.json");
    return doc;
  } catch (const nlohmann::json::exception& e) {
    throw core::IoError("'" + path + "' is not valid JSON: " + e.what());
  }
}

core::ErrorResistanceTable tableFromJson(const nlohmann::json& document) {
  try {
    const auto& rows = document.at("error_resistance");
    const bool sparse = document.at("format") == kSparseFormat;
    core::ErrorResistanceTable table(rows.size());
    for (size_t i = 0; i < rows.size(); ++i) {
      const auto& row = rows[i];
      if (!sparse && row.size() != rows.size())
        throw core::IoError("error_resistance row " + std::to_string(i) + " has " +
                            std::to_string(row.size()) + " values, expected " +
                            std::to_string(rows.size()));
      for (size_t q = 0; q < row.size(); ++q) {
        const auto& v = sparse ? row[q].at(1) : row[q];
        const size_t j = sparse ? row[q].at(0).get<size_t>() : q;
        if (j >= rows.size())
          throw core::IoError("error_resistance row " + std::to_string(i) + " names view " +
                              std::to_string(j) + " of " + std::to_string(rows.size()));
        if (!v.is_null())
          table.set(static_cast<core::ViewId>(i), static_cast<core::ViewId>(j), v.get<double>());
      }
    }
    return table;
  } catch (const nlohmann::json::exception& e) {
    throw core::IoError(std::string("selection.json error_resistance: ") + e.what());
  }
}

std::vector<std::vector<double>> errorResistanceFromJson(const nlohmann::json& document) {
  return tableFromJson(document).dense();
}

}  // namespace view_selection::io
