// The scratch folder the file parsers' targets write their input into: one per process,
// removed at exit (a crash leaves it, with the input that crashed, for a look).
#include "fuzz_target.h"

#include <unistd.h>

#include <cstdio>
#include <filesystem>
#include <stdexcept>

namespace view_selection::fuzz {

namespace {
std::string& folderPath() {
  static std::string path;
  return path;
}
void removeFolder() {
  std::error_code ignored;
  std::filesystem::remove_all(folderPath(), ignored);
}
}  // namespace

std::string scratchFolder() {
  static const std::string folder = [] {
    const char* tmp = std::getenv("TMPDIR");
    const std::filesystem::path base = tmp && *tmp ? tmp : "/tmp";
    const std::filesystem::path dir = base / ("view_selection_fuzz_" + std::to_string(::getpid()));
    std::filesystem::create_directories(dir);
    folderPath() = dir.string();
    std::atexit(removeFolder);
    return dir.string();
  }();
  return folder;
}

std::string writeScratch(const std::string& name, const uint8_t* data, size_t size) {
  const std::string path = scratchFolder() + "/" + name;
  std::FILE* f = std::fopen(path.c_str(), "wb");
  if (!f) throw std::runtime_error("fuzz: cannot write " + path);
  if (size > 0 && std::fwrite(data, 1, size, f) != size) {
    std::fclose(f);
    throw std::runtime_error("fuzz: cannot write " + path);
  }
  std::fclose(f);
  return path;
}

}  // namespace view_selection::fuzz
