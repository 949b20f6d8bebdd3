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
                              const Eigen::Matrix3Xd* points) {
  const Eigen::Quaterniond q = kf.pose.orientation.normalized();
  const core::PinholeIntrinsics& k = kf.intrinsics;
  nlohmann::json j = {
      {"id", id},
      {"stamp", kf.stamp},
      {"image", kf.image_name},
      {"position", {kf.pose.position.x(), kf.pose.position.y(), kf.pose.position.z()}},
      {"orientation_xyzw", {q.x(), q.y(), q.z(), q.w()}},
      {"intrinsics", {k.fx, k.fy, k.cx, k.cy, k.width, k.height}},
      {"num_points", kf.num_points},
  };
  if (points) {
    nlohmann::json list = nlohmann::json::array();
    for (Eigen::Index c = 0; c < points->cols(); ++c)
      list.push_back({(*points)(0, c), (*points)(1, c), (*points)(2, c)});
    j["points"] = std::move(list);
  }
  return j;
}

/// One line per element for the long arrays (keyframes, matrix rows, sets), compact otherwise:
/// readable for a person, and still a single valid JSON document.
void writeReadable(std::ostream& out, const nlohmann::ordered_json& document) {
  out << "{\n";
  bool first = true;
  for (auto it = document.begin(); it != document.end(); ++it) {
    out << (first ? "" : ",\n") << "  " << nlohmann::json(it.key()).dump() << ": ";
    first = false;
    const nlohmann::json& value = it.value();
    const bool nested = value.is_array() && !value.empty() &&
                        (value.front().is_array() || value.front().is_object());
    if (!nested) {
      out << value.dump();
      continue;
    }
    out << "[\n";
    for (size_t q = 0; q < value.size(); ++q)
      out << "    " << value[q].dump() << (q + 1 < value.size() ? ",\n" : "\n");
    out << "  ]";
  }
  out << "\n}\n";
}

}  // namespace

nlohmann::json selectionToJson(const core::SelectionSnapshot& snapshot,
                               const nlohmann::json& params,
                               const core::ErrorResistanceMatrix* points) {
  const size_t n = snapshot.size();
  const core::Selection& selection = snapshot.selection;
  nlohmann::json keyframes = nlohmann::json::array();
  for (size_t i = 0; i < n; ++i) {
    const auto id = static_cast<core::ViewId>(i);
    keyframes.push_back(
        keyframeToJson(id, snapshot.keyframes[i], points ? &points->keyframe(id).points : nullptr));
  }
  nlohmann::json rows = nlohmann::json::array();
  for (size_t i = 0; i < n; ++i) {
    std::vector<nlohmann::json> row(n, nullptr);
    for (const core::TableEntry& e : snapshot.table.row(static_cast<core::ViewId>(i)))
      row[static_cast<size_t>(e.view)] = finiteOrNull(e.value);
    rows.push_back(std::move(row));
  }
  nlohmann::json completed = nlohmann::json::array();
  for (const core::CompletedView& c : selection.completed)
    completed.push_back({{"view", c.view}, {"added_to", c.added_to}});
  nlohmann::json pairs = nlohmann::json::array();
  for (const auto& [a, b] : selection.pairs) pairs.push_back({a, b});
  const auto [s, s_first] = selection.initialPair();

  nlohmann::json doc;
  doc["format"] = "view_selection/1";
  doc["params"] = params;
  doc["keyframes"] = std::move(keyframes);
  doc["error_resistance"] = std::move(rows);
  doc["next_views"] = selection.next_views;
  doc["start_view"] =
      selection.start_view >= 0 ? nlohmann::json(selection.start_view) : nlohmann::json(nullptr);
  doc["initial_pair"] = s >= 0 ? nlohmann::json({s, s_first}) : nlohmann::json(nullptr);
  doc["order"] = selection.order;
  doc["completed"] = std::move(completed);
  doc["isolated"] = selection.isolated;
  doc["final_next_views"] = selection.final_next_views;
  doc["pairs"] = std::move(pairs);
  return doc;
}

nlohmann::json selectionToJson(const core::ErrorResistanceMatrix& matrix,
                               const core::Selection& selection, const nlohmann::json& params,
                               bool dump_points) {
  return selectionToJson(core::makeSnapshot(matrix, selection, {}), params,
                         dump_points ? &matrix : nullptr);
}

void writeSelectionJson(const std::string& path, const core::SelectionSnapshot& snapshot,
                        const nlohmann::json& params, const core::ErrorResistanceMatrix* points) {
  // nlohmann::ordered_json keeps METHOD.md's key order in the file.
  const nlohmann::json doc = selectionToJson(snapshot, params, points);
  nlohmann::ordered_json ordered;
  for (const char* key :
       {"format", "params", "keyframes", "error_resistance", "next_views", "start_view",
        "initial_pair", "order", "completed", "isolated", "final_next_views", "pairs"})
    ordered[key] = doc.at(key);
  std::ostringstream out;
  writeReadable(out, ordered);
  writeFileContents(path, out.str());  // the system's reason on failure (a full disk, ...)
}

void writeSelectionJson(const std::string& path, const core::ErrorResistanceMatrix& matrix,
                        const core::Selection& selection, const nlohmann::json& params,
                        bool dump_points) {
  writeSelectionJson(path, core::makeSnapshot(matrix, selection, {}), params,
                     dump_points ? &matrix : nullptr);
}

void writePairsTxt(const std::string& path, const std::vector<std::string>& image_names,
                   const std::vector<std::pair<core::ViewId, core::ViewId>>& pairs) {
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

void writeMvsPairTxt(const std::string& path, const core::SelectionSnapshot& snapshot) {
  std::ofstream out(path);
  if (!out) throw core::IoError("cannot write '" + path + "'");
  out.precision(9);
  const auto& sets = snapshot.selection.final_next_views;
  out << snapshot.size() << '\n';
  for (size_t i = 0; i < snapshot.size(); ++i) {
    out << i << '\n';
    const std::vector<core::ViewId> none;
    const auto& set = i < sets.size() ? sets[i] : none;
    out << set.size();
    for (const core::ViewId j : set)
      out << ' ' << j << ' ' << 1.0 / snapshot.table.at(static_cast<core::ViewId>(i), j);
    out << '\n';
  }
  if (!out) throw core::IoError("error while writing '" + path + "'");
}

nlohmann::json readSelectionJson(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw core::IoError("cannot read '" + path + "'");
  try {
    nlohmann::json doc = nlohmann::json::parse(in);
    if (!doc.contains("format") || doc["format"] != "view_selection/1")
      throw core::IoError("'" + path + "' is not a view_selection/1 selection.json");
    return doc;
  } catch (const nlohmann::json::exception& e) {
    throw core::IoError("'" + path + "' is not valid JSON: " + e.what());
  }
}

std::vector<std::vector<double>> errorResistanceFromJson(const nlohmann::json& document) {
  std::vector<std::vector<double>> out;
  for (const auto& row : document.at("error_resistance")) {
    out.emplace_back();
    for (const auto& v : row) out.back().push_back(v.is_null() ? core::kInfinity : v.get<double>());
  }
  return out;
}

}  // namespace view_selection::io
