#include "view_selection/session/state_file.h"

#include "view_selection/io/atomic_file.h"
#include "view_selection/io/crc32.h"
#include "view_selection/io/file_ops.h"

#include "state_sections.h"

#include <algorithm>
#include <array>
#include <cstring>

namespace view_selection::session {

namespace {

// docs/state_file.md: the header.
constexpr std::array<uint8_t, 8> kMagic = {0x89, 'V', 'S', 'S', '\r', '\n', 0x1a, '\n'};
constexpr size_t kHeaderSize = 32;

}  // namespace

std::vector<uint8_t> encodeState(const SessionState& state) {
  io::BinaryWriter w;
  encodeContent(w, state);
  const std::vector<uint8_t>& payload = w.bytes;
  io::BinaryWriter h;
  h.raw(kMagic.data(), kMagic.size());
  h.u32(kStateFormatVersion);
  h.u32(static_cast<uint32_t>(kHeaderSize));
  h.u64(payload.size());
  h.u32(io::crc32(payload.data(), payload.size()));
  h.u32(io::crc32(h.bytes.data(), h.bytes.size()));
  h.raw(payload.data(), payload.size());
  return std::move(h.bytes);
}

SessionState decodeState(const uint8_t* data, size_t size, const std::string& name) {
  const std::string what = name.empty() ? "state" : "state file '" + name + "'";
  const size_t signature = std::min(size, kMagic.size());
  if (size == 0 || std::memcmp(data, kMagic.data(), signature) != 0)
    throw io::StateFileError(
        what + (size == 0 ? " is empty"
                          : " is not a view_selection state file (no state file signature)"));
  if (size < kHeaderSize)
    throw io::StateFileError(what + " is truncated: " + std::to_string(size) +
                             " bytes, shorter than the header");
  io::BinaryReader header(data, kHeaderSize, what);
  header.take(kMagic.size(), "signature");
  const uint32_t version = header.u32("version");
  const uint32_t header_size = header.u32("header size");
  const uint64_t payload_size = header.u64("payload size");
  const uint32_t payload_crc = header.u32("checksum");
  const uint32_t header_crc = header.u32("header checksum");
  if (header_crc != io::crc32(data, kHeaderSize - 4))
    throw io::StateFileError(what + " is corrupted: the header's checksum does not match");
  if (version == 0 || version > kStateFormatVersion)
    throw io::StateFileError(what + " has format version " + std::to_string(version) +
                             "; this build reads versions 1 to " +
                             std::to_string(kStateFormatVersion));
  if (header_size != kHeaderSize)
    throw io::StateFileError(what + " has a header of " + std::to_string(header_size) + " bytes");
  if (payload_size != size - kHeaderSize)
    throw io::StateFileError(what + " is truncated or has trailing bytes: the header says " +
                             std::to_string(payload_size) + " bytes of content, the file has " +
                             std::to_string(size - kHeaderSize));
  const uint8_t* payload = data + kHeaderSize;
  if (payload_crc != io::crc32(payload, static_cast<size_t>(payload_size)))
    throw io::StateFileError(what + " is corrupted: the content's checksum does not match");
  io::BinaryReader r(payload, static_cast<size_t>(payload_size), what);
  return decodeContent(r, what);
}

size_t writeStateFile(const std::string& path, const SessionState& state) {
  const std::vector<uint8_t> bytes = encodeState(state);
  io::writeAtomically(path, [&](const std::string& tmp) {
    io::writeFileContents(tmp, bytes.data(), bytes.size());
  });
  return bytes.size();
}

SessionState readStateFile(const std::string& path) {
  const std::vector<uint8_t> bytes = io::readFileBytes(path);
  return decodeState(bytes.data(), bytes.size(), path);
}

}  // namespace view_selection::session
