#include "view_selection/io/file_ops.h"

#include "view_selection/core/exceptions.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <stdio.h>
#include <cerrno>
#include <cstring>
#include <ctime>

namespace view_selection::io {

std::vector<uint8_t> readFileBytes(const std::string& path) {
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) throw core::IoError("cannot open '" + path + "': " + std::strerror(errno));
  std::vector<uint8_t> bytes;
  struct stat st {};
  if (::fstat(fd, &st) == 0 && st.st_size > 0) bytes.reserve(static_cast<size_t>(st.st_size));  // no regrowth
  uint8_t buffer[1 << 16];
  while (true) {
    const ssize_t n = ::read(fd, buffer, sizeof buffer);
    if (n < 0 && errno == EINTR) continue;
    if (n < 0) {
      const int saved = errno;
      ::close(fd);
      throw core::IoError("cannot read '" + path + "': " + std::strerror(saved));
    }
    if (n == 0) break;
    bytes.insert(bytes.end(), buffer, buffer + n);
  }
  ::close(fd);
  return bytes;
}

void appendToFile(const std::string& path, const std::vector<uint8_t>& bytes, bool flush) {
  const int fd = ::open(path.c_str(), O_WRONLY | O_APPEND | O_CREAT | O_CLOEXEC, 0644);
  if (fd < 0) throw core::IoError("cannot open '" + path + "': " + std::strerror(errno));
  size_t done = 0;
  while (done < bytes.size()) {
    const ssize_t n = ::write(fd, bytes.data() + done, bytes.size() - done);
    if (n < 0 && errno == EINTR) continue;
    if (n < 0) {
      const int saved = errno;
      ::close(fd);
      throw core::IoError("cannot append to '" + path + "': " + std::strerror(saved));
    }
    done += static_cast<size_t>(n);
  }
  if (flush && ::fdatasync(fd) != 0) {
    const int saved = errno;
    ::close(fd);
    throw core::IoError("cannot flush '" + path + "': " + std::strerror(saved));
  }
  ::close(fd);
}

void truncateFile(const std::string& path, size_t size) {
  const int fd = ::open(path.c_str(), O_WRONLY | O_CREAT | O_CLOEXEC, 0644);
  if (fd < 0) throw core::IoError("cannot open '" + path + "': " + std::strerror(errno));
  if (::ftruncate(fd, static_cast<off_t>(size)) != 0 || ::fsync(fd) != 0) {
    const int saved = errno;
    ::close(fd);
    throw core::IoError("cannot truncate '" + path + "': " + std::strerror(saved));
  }
  ::close(fd);
}

std::string moveAside(const std::string& path) {
  const std::time_t now = std::time(nullptr);
  std::tm utc{};
  gmtime_r(&now, &utc);
  char stamp[32];
  std::strftime(stamp, sizeof stamp, "%Y%m%dT%H%M%S", &utc);
  const std::string base = path + ".bad-" + stamp;
  for (int n = 0; n < 1000; ++n) {
    const std::string candidate = n == 0 ? base : base + "-" + std::to_string(n);
    // Never over an existing file (rename() would replace it).
    if (::renameat2(AT_FDCWD, path.c_str(), AT_FDCWD, candidate.c_str(), RENAME_NOREPLACE) == 0)
      return candidate;
    // File systems without RENAME_NOREPLACE: a hard link fails on an existing name too.
    if (errno == EINVAL && ::link(path.c_str(), candidate.c_str()) == 0) {
      ::unlink(path.c_str());
      return candidate;
    }
    if (errno != EEXIST)
      throw core::IoError("cannot keep '" + path + "' aside as '" + candidate +
                          "': " + std::strerror(errno));
  }
  throw core::IoError("cannot keep '" + path + "' aside: too many earlier bad copies");
}

}  // namespace view_selection::io
