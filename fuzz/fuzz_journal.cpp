// The state journal (docs/state_file.md, "Journal records"): a base state file and the records
// appended after it. Input: u32 n, then n bytes of a base state file, then the journal's bytes.
// The replay never throws whatever the bytes; what it applies is a prefix of whole records, and
// replaying only that prefix gives the same session with no error; a session it yields encodes
// to a state file that decodes to the same. Each input is tried as it is and again with the
// base's and every record's lengths and checksums made to match, so that mutations reach the
// record decoder and applyDelta instead of stopping at a checksum.
#include "fuzz_target.h"

#include "view_selection/io/crc32.h"
#include "view_selection/session/journal.h"
#include "view_selection/session/state_file.h"

using namespace view_selection;

namespace {

constexpr size_t kBaseHeaderSize = 32;
constexpr size_t kRecordHeaderSize = 24;

uint64_t get64(const std::vector<uint8_t>& b, size_t at) {
  uint64_t v = 0;
  for (int i = 0; i < 8; ++i) v |= static_cast<uint64_t>(b[at + i]) << (8 * i);
  return v;
}
void put32(std::vector<uint8_t>& b, size_t at, uint32_t v) {
  for (int i = 0; i < 4; ++i) b[at + i] = static_cast<uint8_t>(v >> (8 * i));
}
void put64(std::vector<uint8_t>& b, size_t at, uint64_t v) {
  for (int i = 0; i < 8; ++i) b[at + i] = static_cast<uint8_t>(v >> (8 * i));
}

void check(const std::vector<uint8_t>& base, const std::vector<uint8_t>& journal) {
  session::SessionState state;
  try {
    state = session::decodeState(base.data(), base.size());
  } catch (const io::StateFileError&) {
    return;
  }
  const session::SessionState before = state;
  const session::JournalReplay replay = session::replayJournal(state, journal.data(), journal.size());
  if (replay.total_bytes != journal.size()) fuzz::broken("total_bytes is not the journal's size");
  if (replay.good_bytes > journal.size()) fuzz::broken("more good bytes than the journal has");
  if (replay.error.empty() != (replay.good_bytes == journal.size()))
    fuzz::broken("an error without a dropped tail, or a dropped tail without an error");
  if (replay.records == 0 && session::encodeState(state) != session::encodeState(before))
    fuzz::broken("no record applied, yet the session changed");

  // The good prefix alone: the same records, the same session, nothing dropped.
  session::SessionState again = before;
  const session::JournalReplay prefix = session::replayJournal(again, journal.data(), replay.good_bytes);
  if (!prefix.error.empty() || prefix.records != replay.records || prefix.stale != replay.stale)
    fuzz::broken("replaying the good prefix differs from replaying the whole journal");
  const std::vector<uint8_t> encoded = session::encodeState(state);
  if (session::encodeState(again) != encoded) fuzz::broken("the good prefix gives another session");

  // What the replay yields is a session a state file holds.
  try {
    const session::SessionState decoded = session::decodeState(encoded.data(), encoded.size());
    if (session::encodeState(decoded) != encoded) fuzz::broken("a replayed session does not round-trip");
  } catch (const io::StateFileError&) {
    fuzz::broken("a replayed session does not encode to a readable state file");
  }
}

/// The base's payload size and checksums, and each record's checksums, made to match; a record's
/// length is cut to what is there.
void fixChecksums(std::vector<uint8_t>& base, std::vector<uint8_t>& journal) {
  if (base.size() >= kBaseHeaderSize) {
    put64(base, 16, base.size() - kBaseHeaderSize);
    put32(base, 24, io::crc32(base.data() + kBaseHeaderSize, base.size() - kBaseHeaderSize));
    put32(base, 28, io::crc32(base.data(), kBaseHeaderSize - 4));
  }
  size_t pos = 0;
  while (journal.size() - pos >= kRecordHeaderSize) {
    const size_t there = journal.size() - pos - kRecordHeaderSize;
    const uint64_t length = std::min<uint64_t>(get64(journal, pos + 8), there);
    put64(journal, pos + 8, length);
    put32(journal, pos + 16, io::crc32(journal.data() + pos + kRecordHeaderSize, length));
    put32(journal, pos + 20, io::crc32(journal.data() + pos, kRecordHeaderSize - 4));
    pos += kRecordHeaderSize + static_cast<size_t>(length);
  }
}

}  // namespace

VIEW_SELECTION_FUZZ_TARGET(journal) {
  fuzz::Bytes in(data, size);
  const size_t n = std::min<size_t>(in.take<uint32_t>(), size - std::min<size_t>(size, 4));
  const uint8_t* rest = data + std::min<size_t>(size, 4);
  std::vector<uint8_t> base(rest, rest + n);
  std::vector<uint8_t> journal(rest + n, data + size);
  check(base, journal);
  std::vector<uint8_t> fixed_base = base, fixed_journal = journal;
  fixChecksums(fixed_base, fixed_journal);
  if (fixed_base != base || fixed_journal != journal) check(fixed_base, fixed_journal);
}
