#include "view_selection/io/crc32.h"

#include <array>

namespace view_selection::io {

uint32_t crc32(const uint8_t* data, size_t size, uint32_t crc) {
  static const std::array<uint32_t, 256> table = [] {
    std::array<uint32_t, 256> t{};
    for (uint32_t n = 0; n < 256; ++n) {
      uint32_t c = n;
      for (int k = 0; k < 8; ++k) c = (c & 1) ? 0xEDB88320u ^ (c >> 1) : c >> 1;
      t[n] = c;
    }
    return t;
  }();
  crc = ~crc;
  for (size_t q = 0; q < size; ++q) crc = table[(crc ^ data[q]) & 0xFF] ^ (crc >> 8);
  return ~crc;
}

}  // namespace view_selection::io
