// The state file: decoded whatever the bytes; a file that decodes re-encodes to a file that
// decodes to the same; a session that restores can be selected and continued. Each input is
// tried as it is (the header checks) and again with its payload size and both checksums made
// to match (docs/state_file.md: the header), so that mutations reach the sections' parsers
// instead of stopping at the checksum.
#include "fuzz_target.h"

#include "view_selection/core/exceptions.h"
#include "view_selection/io/crc32.h"
#include "view_selection/session/capture.h"
#include "view_selection/session/state_file.h"

using namespace view_selection;

namespace {

constexpr size_t kHeaderSize = 32;

void put32(std::vector<uint8_t>& b, size_t at, uint32_t v) {
  for (int i = 0; i < 4; ++i) b[at + i] = static_cast<uint8_t>(v >> (8 * i));
}

void check(const uint8_t* data, size_t size) {
  session::SessionState state;
  try {
    state = session::decodeState(data, size);
  } catch (const io::StateFileError&) {
    return;
  }
  const std::vector<uint8_t> again = session::encodeState(state);
  try {
    const session::SessionState twice = session::decodeState(again.data(), again.size());
    if (session::encodeState(twice) != again) fuzz::broken("encode(decode(encode(s))) != encode(s)");
  } catch (const io::StateFileError&) {
    fuzz::broken("a re-encoded state file does not decode");
  }
  try {
    auto selector = session::selectorFor(state);
    const core::SelectionOutput snapshot = selector->output();
    if (snapshot.size() != state.selector.keyframes.size()) fuzz::broken("keyframes lost");
    // Continue with one frame (no depth: the depth source refuses it, the others may take it).
    core::Frame frame;
    frame.stamp = (state.selector.last_stamp ? *state.selector.last_stamp : 0.0) + 1.0;
    frame.intrinsics.fx = frame.intrinsics.fy = 100.0;
    frame.intrinsics.cx = 32.0;
    frame.intrinsics.cy = 24.0;
    frame.intrinsics.width = 64;
    frame.intrinsics.height = 48;
    selector->addFrame(frame);
  } catch (const core::Error&) {
  }
}

}  // namespace

VIEW_SELECTION_FUZZ_TARGET(state_file) {
  check(data, size);
  if (size < kHeaderSize) return;
  std::vector<uint8_t> fixed(data, data + size);
  const uint64_t payload = size - kHeaderSize;
  for (int i = 0; i < 8; ++i) fixed[16 + i] = static_cast<uint8_t>(payload >> (8 * i));
  put32(fixed, 24, io::crc32(fixed.data() + kHeaderSize, fixed.size() - kHeaderSize));
  put32(fixed, 28, io::crc32(fixed.data(), kHeaderSize - 4));
  if (fixed != std::vector<uint8_t>(data, data + size)) check(fixed.data(), fixed.size());
}
