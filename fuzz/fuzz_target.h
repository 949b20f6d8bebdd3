// One fuzz target = one function of (bytes, size). Built with VIEW_SELECTION_LIBFUZZER
// (dev/fuzz, clang -fsanitize=fuzzer) it is libFuzzer's entry point; otherwise it registers
// itself so that test_fuzz_inputs replays the committed corpus and every regression input in the
// normal suite. A target catches the errors its input may cause on purpose (core::Error: a clear
// message); anything else (a crash, another exception, a broken invariant) is a finding.
#pragma once

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <map>
#include <string>
#include <vector>

namespace view_selection::fuzz {

using Target = void (*)(const uint8_t* data, size_t size);

inline std::map<std::string, Target>& targets() {
  static std::map<std::string, Target> all;
  return all;
}

struct Register {
  Register(const char* name, Target target) { targets()[name] = target; }
};

/// A broken invariant: abort, so that libFuzzer records the input (and the replay test fails).
[[noreturn]] inline void broken(const char* what) {
  std::fprintf(stderr, "fuzz invariant broken: %s\n", what);
  std::abort();
}

/// Reads typed values off the input, front to back; past the end everything reads as zero.
class Bytes {
 public:
  Bytes(const uint8_t* data, size_t size) : data_(data), size_(size) {}
  size_t left() const { return size_ - pos_; }
  template <typename T>
  T take() {
    T value{};
    const size_t n = std::min(sizeof(T), left());
    std::memcpy(&value, data_ + pos_, n);
    pos_ += n;
    return value;
  }
  /// A value in [0, bound).
  uint32_t below(uint32_t bound) { return bound == 0 ? 0 : take<uint32_t>() % bound; }
  std::string text(size_t max) {
    const size_t n = std::min<size_t>(below(static_cast<uint32_t>(max + 1)), left());
    std::string s(reinterpret_cast<const char*>(data_ + pos_), n);
    pos_ += n;
    return s;
  }
  std::vector<uint8_t> rest() {
    std::vector<uint8_t> out(data_ + pos_, data_ + size_);
    pos_ = size_;
    return out;
  }
  std::vector<uint8_t> bytes(size_t n) {
    n = std::min(n, left());
    std::vector<uint8_t> out(data_ + pos_, data_ + pos_ + n);
    pos_ += n;
    return out;
  }

 private:
  const uint8_t* data_;
  size_t size_;
  size_t pos_ = 0;
};

/// A scratch folder of this process (under $TMPDIR), for parsers that read files.
std::string scratchFolder();
/// Writes `size` bytes to scratchFolder()/name; returns the path.
std::string writeScratch(const std::string& name, const uint8_t* data, size_t size);

}  // namespace view_selection::fuzz

#if defined(VIEW_SELECTION_LIBFUZZER)
#define VIEW_SELECTION_FUZZ_TARGET(name)                                    \
  static void fuzz_##name(const uint8_t* data, size_t size);                \
  extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) { \
    fuzz_##name(data, size);                                                \
    return 0;                                                               \
  }                                                                         \
  static void fuzz_##name(const uint8_t* data, size_t size)
#else
#define VIEW_SELECTION_FUZZ_TARGET(name)                                             \
  static void fuzz_##name(const uint8_t* data, size_t size);                         \
  static const ::view_selection::fuzz::Register register_##name(#name, fuzz_##name); \
  static void fuzz_##name(const uint8_t* data, size_t size)
#endif
