#include "view_selection/refine/tracks.h"

#include "view_selection/core/exceptions.h"
#include "view_selection/io/file_ops.h"

#include <algorithm>
#include <cstring>
#include <numeric>
#include <fstream>
#include <string_view>
#include <unordered_map>

namespace view_selection::refine {

namespace {

constexpr char kMagic[8] = {'V', 'S', 'M', 'A', 'T', 'C', 'H', '1'};

/// Every image's 2D point indices as one dense table: each image a block as long as its largest
/// index seen, looked up once a run of a pair's matches (the matches come pair by pair; 7.3
/// million lookups at 30 minutes, each of which allocated a map node to find the image there
/// already: emplace, not try_emplace). slot() gives an observation's place in the table.
class DenseObservations {
 public:
  /// Where the last lookup of one side of the matches went.
  struct Last {
    int image = 0;
    size_t block = 0;
    bool set = false;
  };

  explicit DenseObservations(const std::vector<Match>& matches) {
    Last side[2];
    for (const Match& m : matches)
      for (int k = 0; k < 2; ++k) {
        const Observation& o = k == 0 ? m.a : m.b;
        if (o.point2D_idx < 0) continue;
        uint32_t& length = block_length_[blockOf(o.image_id, side[k])];
        length = std::max(length, static_cast<uint32_t>(o.point2D_idx) + 1);
      }
    block_start_.assign(block_length_.size() + 1, 0);
    for (size_t b = 0; b < block_length_.size(); ++b) block_start_[b + 1] = block_start_[b] + block_length_[b];
  }

  size_t size() const { return block_start_.back(); }

  /// The block of an image seen in the matches.
  size_t blockOf(int image, Last& last) {
    if (last.set && last.image == image) return last.block;
    const auto [it, added] = block_of_.try_emplace(image, block_length_.size());
    if (added) block_length_.push_back(0);
    last = {image, it->second, true};
    return it->second;
  }

  /// The table's slot of an observation (point2D_idx >= 0) of an image seen in the matches.
  size_t slot(const Observation& o, size_t block) const {
    return block_start_[block] + static_cast<size_t>(o.point2D_idx);
  }

 private:
  std::unordered_map<int, size_t> block_of_;  // image id -> its block's number
  std::vector<uint32_t> block_length_;
  std::vector<size_t> block_start_;
};

}  // namespace

size_t countObservations(const std::vector<Match>& matches) {
  DenseObservations table(matches);
  std::vector<uint8_t> seen(table.size(), 0);
  size_t n = 0;
  DenseObservations::Last last[2];
  for (const Match& m : matches)
    for (int k = 0; k < 2; ++k) {
      const Observation& o = k == 0 ? m.a : m.b;
      if (o.point2D_idx < 0) continue;
      uint8_t& s = seen[table.slot(o, table.blockOf(o.image_id, last[k]))];
      n += s == 0;
      s = 1;
    }
  return n;
}

Tracks buildTracks(const std::vector<Match>& matches) {
  // Observations are numbered in the order they first appear, through a dense table of every
  // image's 2D point indices: a 30-minute session's 3.7 million matches took 1 s through a hash
  // map of observations and a vector per observation, and longer through a sorted array's
  // binary searches.
  DenseObservations table(matches);
  constexpr uint32_t kNone = static_cast<uint32_t>(-1);
  std::vector<uint32_t> number(table.size(), kNone);  // dense slot -> observation number
  std::vector<Observation> observations;
  std::vector<uint32_t> image_block;  // by observation: its image's block
  DenseObservations::Last seen[2];  // every image has its block now: blockOf only finds them
  const auto indexOf = [&](const Observation& o, DenseObservations::Last& last) -> uint32_t {
    if (o.point2D_idx < 0) return kNone;
    const size_t block = table.blockOf(o.image_id, last);
    uint32_t& q = number[table.slot(o, block)];
    if (q == kNone) {
      q = static_cast<uint32_t>(observations.size());
      observations.push_back(o);
      image_block.push_back(static_cast<uint32_t>(block));
    }
    return q;
  };
  // Observations are numbered (in the order they first appear) before the union-find, so that
  // its arrays are made once at their size: grown a match at a time, they were moved again and
  // again (a 30-minute session's 3.7 million matches: a third of refine_model's setup was
  // memmove, malloc and page faults).
  std::vector<std::pair<uint32_t, uint32_t>> ends(matches.size());
  for (size_t q = 0; q < matches.size(); ++q) ends[q] = {indexOf(matches[q].a, seen[0]), indexOf(matches[q].b, seen[1])};
  const size_t n = observations.size();
  // Union-find; each root keeps its members as a list (next), from its head to its tail, and
  // (once it has two) its images' blocks, sorted, in a list of its own (images[list[root]]):
  // whether two tracks share an image is then a search of the smaller's images in the larger's,
  // not a walk of every pair of members (a point seen from hundreds of keyframes made that
  // quadratic). Lists of roots merged away are used again.
  std::vector<uint32_t> parent(n), size(n, 1), next(n, kNone), head(n), tail(n), list(n, kNone);
  std::iota(parent.begin(), parent.end(), 0u);
  std::iota(head.begin(), head.end(), 0u);
  std::iota(tail.begin(), tail.end(), 0u);
  std::vector<std::vector<uint32_t>> images;
  std::vector<uint32_t> free_lists;
  const auto find = [&](uint32_t x) {
    while (parent[x] != x) x = parent[x] = parent[parent[x]];
    return x;
  };
  std::vector<uint32_t> one_a(1), one_b(1), merged;
  const auto imagesOf = [&](uint32_t root, std::vector<uint32_t>& one) -> const std::vector<uint32_t>& {
    if (size[root] > 1) return images[list[root]];
    one[0] = image_block[root];
    return one;
  };
  Tracks out;
  for (const auto& [a, b] : ends) {
    if (a == kNone || b == kNone) continue;
    uint32_t ra = find(a), rb = find(b);
    if (ra == rb) continue;
    if (size[ra] < size[rb]) std::swap(ra, rb);
    const std::vector<uint32_t>& larger = imagesOf(ra, one_a);
    const std::vector<uint32_t>& smaller = imagesOf(rb, one_b);
    // Two keypoints of one image in one track: leave this match out.
    if (std::any_of(smaller.begin(), smaller.end(),
                    [&](uint32_t i) { return std::binary_search(larger.begin(), larger.end(), i); })) {
      ++out.conflicts;
      continue;
    }
    merged.clear();
    std::merge(larger.begin(), larger.end(), smaller.begin(), smaller.end(), std::back_inserter(merged));
    if (list[ra] == kNone) {
      if (free_lists.empty()) {
        list[ra] = static_cast<uint32_t>(images.size());
        images.emplace_back();
      } else {
        list[ra] = free_lists.back();
        free_lists.pop_back();
      }
    }
    images[list[ra]].swap(merged);
    if (list[rb] != kNone) {
      images[list[rb]].clear();  // its buffer kept for the list's next root
      free_lists.push_back(list[rb]);
      list[rb] = kNone;
    }
    parent[rb] = ra;
    size[ra] += size[rb];
    next[tail[ra]] = head[rb];
    tail[ra] = tail[rb];
  }
  for (uint32_t r = 0; r < parent.size(); ++r) {
    if (parent[r] != r || size[r] < 2) continue;
    std::vector<Observation> track;
    track.reserve(size[r]);
    for (uint32_t q = head[r]; q != kNone; q = next[q]) track.push_back(observations[q]);
    std::sort(track.begin(), track.end(), [](const Observation& x, const Observation& y) {
      return x.image_id != y.image_id ? x.image_id < y.image_id : x.point2D_idx < y.point2D_idx;
    });
    out.tracks.push_back(std::move(track));
  }
  return out;
}

std::vector<Match> readMatches(const std::string& path) {
  const std::vector<uint8_t> bytes = io::readFileBytes(path);  // 58 MB at 30 minutes: not a character at a time
  const std::string_view data(reinterpret_cast<const char*>(bytes.data()), bytes.size());
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
