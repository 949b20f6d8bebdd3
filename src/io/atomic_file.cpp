#include "view_selection/io/atomic_file.h"

#include "view_selection/core/exceptions.h"

#include <fcntl.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <cstring>
#include <filesystem>
#include <memory>
#include <streambuf>

namespace view_selection::io {

namespace {

namespace fs = std::filesystem;

/// fsync of a file or folder by path; false with errno set on failure.
bool syncPath(const std::string& path, int flags) {
  const int fd = ::open(path.c_str(), flags);
  if (fd < 0) return false;
  const bool ok = ::fsync(fd) == 0;
  const int saved = errno;
  ::close(fd);
  errno = saved;
  return ok;
}

/// A hidden name beside `path` that keeps its extension (writers such as cv::imwrite choose the
/// format by it): "dir/.name.tmp-<pid>-<n>.png".
std::string temporaryPath(const fs::path& path) {
  static std::atomic<unsigned> counter{0};
  const std::string name = "." + path.stem().string() + ".tmp-" + std::to_string(::getpid()) + "-" +
                           std::to_string(counter++) + path.extension().string();
  return (path.parent_path() / name).string();
}

}  // namespace

void writeFileContents(const std::string& path, const void* data, size_t size) {
  const int fd = ::open(path.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (fd < 0) throw core::IoError("cannot create '" + path + "': " + std::strerror(errno));
  const char* bytes = static_cast<const char*>(data);
  size_t done = 0;
  while (done < size) {
    const ssize_t n = ::write(fd, bytes + done, size - done);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) {
      const int saved = n < 0 ? errno : EIO;
      ::close(fd);
      throw core::IoError("cannot write '" + path + "': " + std::strerror(saved));
    }
    done += static_cast<size_t>(n);
  }
  if (::close(fd) != 0) throw core::IoError("cannot write '" + path + "': " + std::strerror(errno));
}

namespace {

/// An output buffer onto a file descriptor that remembers the first write error's errno.
class FdBuffer : public std::streambuf {
 public:
  explicit FdBuffer(int fd) : fd_(fd) { setp(buffer_, buffer_ + sizeof buffer_); }
  int error() const { return error_; }
  int sync() override { return drain() ? 0 : -1; }

 protected:
  int_type overflow(int_type c) override {
    if (!drain()) return traits_type::eof();
    if (!traits_type::eq_int_type(c, traits_type::eof())) {
      *pptr() = traits_type::to_char_type(c);
      pbump(1);
    }
    return traits_type::not_eof(c);
  }

 private:
  bool drain() {
    const char* p = pbase();
    while (p < pptr()) {
      const ssize_t n = ::write(fd_, p, static_cast<size_t>(pptr() - p));
      if (n < 0 && errno == EINTR) continue;
      if (n <= 0) {
        if (!error_) error_ = n < 0 ? errno : EIO;
        return false;
      }
      p += n;
    }
    setp(buffer_, buffer_ + sizeof buffer_);
    return true;
  }

  int fd_;
  int error_ = 0;
  char buffer_[1 << 16];
};

}  // namespace

void writeFileStreaming(const std::string& path, const std::function<void(std::ostream&)>& write) {
  const int fd = ::open(path.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (fd < 0) throw core::IoError("cannot create '" + path + "': " + std::strerror(errno));
  auto buffer = std::make_unique<FdBuffer>(fd);
  std::ostream out(buffer.get());
  try {
    write(out);
  } catch (...) {
    ::close(fd);
    throw;
  }
  out.flush();
  const int error = buffer->error() ? buffer->error() : (out ? 0 : EIO);
  if (::close(fd) != 0 && error == 0)
    throw core::IoError("cannot write '" + path + "': " + std::strerror(errno));
  if (error) throw core::IoError("cannot write '" + path + "': " + std::strerror(error));
}

bool syncFolder(const std::string& folder) { return syncPath(folder, O_RDONLY | O_DIRECTORY); }

void writeAtomically(const std::string& path,
                     const std::function<void(const std::string&)>& write) {
  const fs::path target(path);
  const std::string tmp = temporaryPath(target);
  try {
    write(tmp);
    if (!syncPath(tmp, O_RDONLY))
      throw core::IoError("cannot flush '" + tmp + "' to disk: " + std::strerror(errno));
    if (::rename(tmp.c_str(), path.c_str()) != 0)
      throw core::IoError("cannot rename '" + tmp + "' to '" + path + "': " + std::strerror(errno));
  } catch (...) {
    std::error_code ignored;
    fs::remove(tmp, ignored);
    throw;
  }
  // The rename is durable once the folder's entry is on disk; a failure here loses nothing.
  const fs::path folder = target.parent_path().empty() ? fs::path(".") : target.parent_path();
  syncPath(folder.string(), O_RDONLY | O_DIRECTORY);
}

}  // namespace view_selection::io
