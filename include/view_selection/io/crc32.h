// CRC-32 (IEEE 802.3, as zlib's crc32()): the checksums of the state file and its journal.
#pragma once

#include <cstddef>
#include <cstdint>

namespace view_selection::io {

/// CRC-32 of `size` bytes, continuing from `crc`.
uint32_t crc32(const uint8_t* data, size_t size, uint32_t crc = 0);

}  // namespace view_selection::io
