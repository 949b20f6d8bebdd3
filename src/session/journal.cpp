#include "view_selection/session/journal.h"

#include "view_selection/io/binary_codec.h"
#include "view_selection/io/crc32.h"
#include "view_selection/io/file_ops.h"
#include "view_selection/session/state_file.h"

#include "state_sections.h"

#include <unistd.h>

#include <algorithm>
#include <array>
#include <cstring>
#include <type_traits>

namespace view_selection::session {

// docs/state_file.md, "The journal" and "Journal records".

namespace {

constexpr std::array<uint8_t, 4> kJournalMagic = {'V', 'S', 'J', 'R'};
constexpr uint32_t kJournalVersion = 1;
constexpr size_t kRecordHeaderSize = 24;

/// The trailer of a record: `rest` without keyframes and rows (whatever it holds).
SessionState trailerOf(const SessionState& rest) {
  SessionState t;
  t.producer = rest.producer;
  t.saved_at = rest.saved_at;
  t.selector.config = rest.selector.config;
  t.selector.policy = rest.selector.policy;
  t.selector.last_stamp = rest.selector.last_stamp;
  t.points = rest.points;
  t.statistics = rest.statistics;
  t.pair_sequence = rest.pair_sequence;
  return t;
}

SessionDelta decodeRecord(io::BinaryReader& r, uint64_t& base_id, uint64_t& index,
                          const std::string& what) {
  SessionDelta d;
  base_id = r.u64("base id");
  index = r.u64("record index");
  d.keyframe_count = r.u64("keyframe count");
  d.keyframes.resize(r.count(4 + 117, "changed keyframes"));
  for (auto& [id, k] : d.keyframes) {
    id = r.i32("keyframe id");
    readKeyframe(r, k);
  }
  d.rows.resize(r.count(4 + 8, "changed rows"));
  for (auto& [id, row] : d.rows) {
    id = r.i32("row id");
    readRow(r, row);
  }
  d.rest = decodeContent(r, what);
  // The record's keyframes' revisit_of (ascending id both).
  auto k = d.keyframes.begin();
  for (const auto& [id, earlier] : d.rest.revisit_links) {
    while (k != d.keyframes.end() && k->first < id) ++k;
    if (k == d.keyframes.end() || k->first != id)
      r.fail("a revisit link names keyframe " + std::to_string(id) + ", not in the record");
    k->second.revisit_of = earlier;
  }
  d.rest.revisit_links.clear();
  return d;
}

}  // namespace

void applyDelta(SessionState& state, const SessionDelta& delta) {
  const auto fail = [](const std::string& why) {
    throw io::StateFileError("journal record does not fit its state: " + why);
  };
  const uint64_t n = delta.keyframe_count;
  const size_t before = std::min<size_t>(state.selector.keyframes.size(), n);
  // Every new keyframe and row must be in the record; every id in range, ascending.
  const auto check = [&](const auto& list, const char* what) {
    uint64_t next_new = before;
    int64_t last = -1;
    for (const auto& [id, value] : list) {
      if (id < 0 || static_cast<uint64_t>(id) >= n || id <= last)
        fail(std::string(what) + " id " + std::to_string(id) + " out of range or order");
      last = id;
      if (static_cast<uint64_t>(id) >= before) {
        if (static_cast<uint64_t>(id) != next_new) fail(std::string("new ") + what + " missing");
        ++next_new;
      }
    }
    if (next_new != n) fail(std::string("new ") + what + " missing");
  };
  check(delta.keyframes, "keyframe");
  check(delta.rows, "row");
  state.selector.keyframes.resize(n);
  state.selector.rows.resize(n);
  for (const auto& [id, k] : delta.keyframes) state.selector.keyframes[static_cast<size_t>(id)] = k;
  for (const auto& [id, row] : delta.rows) state.selector.rows[static_cast<size_t>(id)] = row;
  const SessionState& t = delta.rest;
  state.producer = t.producer;
  state.saved_at = t.saved_at;
  state.selector.config = t.selector.config;
  state.selector.policy = t.selector.policy;
  state.selector.last_stamp = t.selector.last_stamp;
  state.points = t.points;
  state.statistics = t.statistics;
  state.pair_sequence = t.pair_sequence;
}

void mergeDelta(SessionDelta& earlier, SessionDelta later) {
  const auto merge = [&](auto& a, auto& b) {
    // Both ascending by id: later's entries win; ids at or beyond the new count go.
    std::decay_t<decltype(a)> out;
    out.reserve(a.size() + b.size());
    size_t p = 0, q = 0;
    while (p < a.size() || q < b.size()) {
      if (q == b.size() || (p < a.size() && a[p].first < b[q].first)) {
        if (static_cast<uint64_t>(a[p].first) < later.keyframe_count)
          out.push_back(std::move(a[p]));
        ++p;
      } else {
        if (p < a.size() && a[p].first == b[q].first) ++p;
        out.push_back(std::move(b[q++]));
      }
    }
    a = std::move(out);
  };
  merge(earlier.keyframes, later.keyframes);
  merge(earlier.rows, later.rows);
  earlier.keyframe_count = later.keyframe_count;
  earlier.rest = std::move(later.rest);
}

std::vector<uint8_t> encodeJournalRecord(uint64_t base_id, uint64_t index,
                                         const SessionDelta& delta) {
  io::BinaryWriter w;
  w.u64(base_id);
  w.u64(index);
  w.u64(delta.keyframe_count);
  w.u64(delta.keyframes.size());
  for (const auto& [id, k] : delta.keyframes) {
    w.i32(id);
    writeKeyframe(w, k);
  }
  w.u64(delta.rows.size());
  for (const auto& [id, row] : delta.rows) {
    w.i32(id);
    writeRow(w, row);
  }
  SessionState trailer = trailerOf(delta.rest);
  for (const auto& [id, k] : delta.keyframes)
    if (k.revisit_of >= 0) trailer.revisit_links.emplace_back(id, k.revisit_of);
  encodeContent(w, trailer);
  io::BinaryWriter h;
  h.raw(kJournalMagic.data(), kJournalMagic.size());
  h.u32(kJournalVersion);
  h.u64(w.bytes.size());
  h.u32(io::crc32(w.bytes.data(), w.bytes.size()));
  h.u32(io::crc32(h.bytes.data(), h.bytes.size()));
  h.raw(w.bytes.data(), w.bytes.size());
  return std::move(h.bytes);
}

JournalReplay replayJournal(SessionState& state, const uint8_t* data, size_t size,
                            const std::string& name) {
  JournalReplay out;
  out.total_bytes = size;
  const std::string what = name.empty() ? "journal" : "journal '" + name + "'";
  size_t pos = 0;
  uint64_t expected = 0;  // the next record index of this base
  while (pos < size) {
    const auto stop = [&](const std::string& why) {
      out.error = what + ": " + why + " at byte " + std::to_string(pos) + " (record " +
                  std::to_string(out.records + out.stale) + "); the " + std::to_string(size - pos) +
                  " bytes from there on are dropped";
    };
    if (size - pos < kRecordHeaderSize) {
      stop("a torn record header");
      break;
    }
    const uint8_t* h = data + pos;
    io::BinaryReader header(h, kRecordHeaderSize, what);
    if (std::memcmp(header.take(4, "signature"), kJournalMagic.data(), 4) != 0) {
      stop("no record signature");
      break;
    }
    const uint32_t version = header.u32("version");
    const uint64_t length = header.u64("record length");
    const uint32_t payload_crc = header.u32("record checksum");
    const uint32_t header_crc = header.u32("record header checksum");
    if (header_crc != io::crc32(h, kRecordHeaderSize - 4)) {
      stop("a record header whose checksum does not match");
      break;
    }
    if (version != kJournalVersion) {
      stop("a record of version " + std::to_string(version));
      break;
    }
    if (length > size - pos - kRecordHeaderSize) {
      stop("a torn record (" + std::to_string(length) + " bytes announced, " +
           std::to_string(size - pos - kRecordHeaderSize) + " there)");
      break;
    }
    const uint8_t* payload = h + kRecordHeaderSize;
    if (payload_crc != io::crc32(payload, static_cast<size_t>(length))) {
      stop("a record whose checksum does not match");
      break;
    }
    try {
      io::BinaryReader r(payload, static_cast<size_t>(length), what);
      uint64_t base_id = 0, index = 0;
      SessionDelta delta = decodeRecord(r, base_id, index, what);
      if (!state.base_id || base_id != *state.base_id) {
        ++out.stale;  // of an earlier base: the base holds it already
      } else {
        if (index != expected)
          throw io::StateFileError("record " + std::to_string(index) + " where " +
                                   std::to_string(expected) + " was due");
        applyDelta(state, delta);
        ++expected;
        ++out.records;
      }
    } catch (const core::Error& e) {
      stop(e.what());
      break;
    }
    pos += kRecordHeaderSize + static_cast<size_t>(length);
    out.good_bytes = pos;
  }
  return out;
}

std::string journalPath(const std::string& path) { return path + ".journal"; }

SessionState readSession(const std::string& path, JournalReplay* replay) {
  SessionState state = readStateFile(path);
  const std::string journal = journalPath(path);
  JournalReplay r;
  if (::access(journal.c_str(), F_OK) == 0) {
    const std::vector<uint8_t> bytes = io::readFileBytes(journal);
    r = replayJournal(state, bytes.data(), bytes.size(), journal);
  }
  if (replay) *replay = r;
  return state;
}

}  // namespace view_selection::session
