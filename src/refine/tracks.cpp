#include "view_selection/refine/tracks.h"

#include "view_selection/core/exceptions.h"

#include <algorithm>
#include <cstring>
#include <fstream>
#include <iterator>
#include <unordered_map>

namespace view_selection::refine {

namespace {

uint64_t keyOf(const Observation& o) {
  return (static_cast<uint64_t>(static_cast<uint32_t>(o.image_id)) << 32) | static_cast<uint32_t>(o.point2D_idx);
}

constexpr char kMagic[8] = {'V', 'S', 'M', 'A', 'T', 'C', 'H', '1'};

}  // namespace

Tracks buildTracks(const std::vector<Match>& matches) {
  std::unordered_map<uint64_t, size_t> index;
  std::vector<Observation> observations;
  const auto indexOf = [&](const Observation& o) {
    const auto [it, added] = index.emplace(keyOf(o), observations.size());
    if (added) observations.push_back(o);
    return it->second;
  };
  std::vector<size_t> parent;
  std::vector<std::vector<size_t>> members;  // by root
  const auto find = [&](size_t x) {
    while (parent[x] != x) x = parent[x] = parent[parent[x]];
    return x;
  };
  Tracks out;
  for (const Match& m : matches) {
    const size_t a = indexOf(m.a), b = indexOf(m.b);
    while (parent.size() < observations.size()) {
      parent.push_back(parent.size());
      members.push_back({members.size()});
    }
    size_t ra = find(a), rb = find(b);
    if (ra == rb) continue;
    // Two keypoints of one image in one track: leave this match out.
    bool conflict = false;
    for (size_t p : members[ra]) {
      for (size_t q : members[rb])
        if (observations[p].image_id == observations[q].image_id) {
          conflict = true;
          break;
        }
      if (conflict) break;
    }
    if (conflict) {
      ++out.conflicts;
      continue;
    }
    if (members[ra].size() < members[rb].size()) std::swap(ra, rb);
    parent[rb] = ra;
    members[ra].insert(members[ra].end(), members[rb].begin(), members[rb].end());
    members[rb].clear();
  }
  for (size_t r = 0; r < members.size(); ++r) {
    if (members[r].size() < 2 || find(r) != r) continue;
    std::vector<Observation> track;
    for (size_t q : members[r]) track.push_back(observations[q]);
    std::sort(track.begin(), track.end(), [](const Observation& x, const Observation& y) {
      return x.image_id != y.image_id ? x.image_id < y.image_id : x.point2D_idx < y.point2D_idx;
    });
    out.tracks.push_back(std::move(track));
  }
  return out;
}

std::vector<Match> readMatches(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw core::IoError(path + ": cannot open the matches file");
  const std::string data((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  if (data.size() < 16 || std::memcmp(data.data(), kMagic, 8) != 0)
    throw core::IoError(path + ": not a matches file (VSMATCH1)");
  uint64_t count = 0;
  std::memcpy(&count, data.data() + 8, 8);
  if (count > (data.size() - 16) / 16 || data.size() != 16 + 16 * count)
    throw core::IoError(path + ": " + std::to_string(count) + " matches do not fit its " +
                        std::to_string(data.size()) + " bytes");
  std::vector<Match> out(count);
  for (uint64_t q = 0; q < count; ++q) {
    int32_t v[4];
    std::memcpy(v, data.data() + 16 + 16 * q, 16);
    out[q] = {{v[0], v[1]}, {v[2], v[3]}};
  }
  return out;
}

void writeMatches(const std::string& path, const std::vector<Match>& matches) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  if (!out) throw core::IoError(path + ": cannot write the matches file");
  out.write(kMagic, 8);
  const uint64_t count = matches.size();
  out.write(reinterpret_cast<const char*>(&count), 8);
  for (const Match& m : matches) {
    const int32_t v[4] = {m.a.image_id, m.a.point2D_idx, m.b.image_id, m.b.point2D_idx};
    out.write(reinterpret_cast<const char*>(v), 16);
  }
  if (!out) throw core::IoError(path + ": writing the matches file failed");
}

}  // namespace view_selection::refine
