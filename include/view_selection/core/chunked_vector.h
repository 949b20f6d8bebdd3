// A vector in chunks of 256 elements, shared between copies until one of them changes a chunk
// (copy on write). Copying one costs a pointer a chunk, so the node can hand readers a copy of a
// 100,000-view structure after every keyframe: the copy shares every chunk, and the next change
// copies only the chunks it touches.
//
// Which chunks a vector may change in place is decided by sharing epochs, not by reference
// counts: a chunk created (or copied) by a vector carries the vector's epoch, and every copy gives
// both the copy and the original a new epoch, so neither changes a chunk the other can still
// read. Readers never write, and no reference count is read to decide, so this is race-free by
// construction (also to ThreadSanitizer). Only one thread may change a given vector; copies of
// it may be read and copied anywhere.
#pragma once

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <initializer_list>
#include <iterator>
#include <stdexcept>
#include <type_traits>
#include <memory>
#include <utility>
#include <vector>

namespace view_selection::core {

/// A value no vector (of any type) has had as its epoch before.
inline std::uint64_t newSharingEpoch() {
  static std::atomic<std::uint64_t> next{1};
  return next.fetch_add(1, std::memory_order_relaxed);
}

/// The epoch of a shared structure: a new one at construction and whenever it is copied from
/// (also from a const object, which is why it is atomic).
class SharingEpoch {
 public:
  SharingEpoch() : value_(newSharingEpoch()) {}
  SharingEpoch(const SharingEpoch& other) : value_(newSharingEpoch()) { other.renew(); }
  SharingEpoch& operator=(const SharingEpoch& other) {
    if (this != &other) {
      renew();
      other.renew();
    }
    return *this;
  }
  /// A moved-to structure owns what the moved-from one owned; the moved-from one owns nothing.
  SharingEpoch(SharingEpoch&& other) noexcept : value_(other.get()) { other.renew(); }
  SharingEpoch& operator=(SharingEpoch&& other) noexcept {
    if (this != &other) {
      value_.store(other.get(), std::memory_order_relaxed);
      other.renew();
    }
    return *this;
  }
  std::uint64_t get() const { return value_.load(std::memory_order_relaxed); }
  void renew() const { value_.store(newSharingEpoch(), std::memory_order_relaxed); }

 private:
  mutable std::atomic<std::uint64_t> value_;
};

template <typename T>
class ChunkedVector {
 public:
  static constexpr std::size_t kChunkBits = 8;
  static constexpr std::size_t kChunk = std::size_t{1} << kChunkBits;

  ChunkedVector() = default;
  ChunkedVector(const ChunkedVector&) = default;
  ChunkedVector& operator=(const ChunkedVector&) = default;
  ChunkedVector(ChunkedVector&& o) noexcept
      : slots_(std::move(o.slots_)), size_(o.size_), epoch_(std::move(o.epoch_)) {
    o.slots_.clear();
    o.size_ = 0;
  }
  ChunkedVector& operator=(ChunkedVector&& o) noexcept {
    if (this != &o) {
      slots_ = std::move(o.slots_);
      size_ = o.size_;
      epoch_ = std::move(o.epoch_);
      o.slots_.clear();
      o.size_ = 0;
    }
    return *this;
  }
  ChunkedVector(std::size_t n, const T& value) { resize(n, value); }
  ChunkedVector(std::initializer_list<T> values) {
    for (const T& v : values) push_back(v);
  }
  template <typename It, typename = std::enable_if_t<!std::is_integral_v<It>>>
  ChunkedVector(It first, It last) {
    for (; first != last; ++first) push_back(*first);
  }

  std::size_t size() const { return size_; }
  bool empty() const { return size_ == 0; }
  const T& operator[](std::size_t i) const {
    return (*slots_[i >> kChunkBits].chunk)[i & (kChunk - 1)];
  }
  const T& at(std::size_t i) const {
    if (i >= size_) throw std::out_of_range("ChunkedVector::at");
    return (*this)[i];
  }
  const T& front() const { return (*this)[0]; }
  const T& back() const { return (*this)[size_ - 1]; }

  /// Element i to change: its chunk is copied first when a copy of this vector may read it.
  T& edit(std::size_t i) { return chunkToEdit(i >> kChunkBits)[i & (kChunk - 1)]; }
  void set(std::size_t i, T value) { edit(i) = std::move(value); }

  void push_back(T value) {
    if ((size_ & (kChunk - 1)) == 0) {
      auto chunk = std::make_shared<std::vector<T>>();
      chunk->reserve(kChunk);
      slots_.push_back({std::move(chunk), epoch_.get()});
    }
    chunkToEdit(slots_.size() - 1).push_back(std::move(value));
    ++size_;
  }
  void pop_back() { resize(size_ - 1); }
  /// Grows with `value`, or truncates.
  void resize(std::size_t n, const T& value = T()) {
    if (n >= size_) {
      while (size_ < n) push_back(value);
      return;
    }
    const std::size_t chunks = (n + kChunk - 1) >> kChunkBits;
    slots_.resize(chunks);
    size_ = n;
    if (chunks > 0) chunkToEdit(chunks - 1).resize(n - ((chunks - 1) << kChunkBits));
  }
  void clear() {
    slots_.clear();
    size_ = 0;
  }
  /// Copies of the elements, in order.
  std::vector<T> toVector() const {
    std::vector<T> out;
    out.reserve(size_);
    for (const Slot& s : slots_) out.insert(out.end(), s.chunk->begin(), s.chunk->end());
    return out;
  }
  /// Chunks this vector shares with others (for tests and benchmarks).
  std::size_t chunkCount() const { return slots_.size(); }

  class const_iterator {
   public:
    using iterator_category = std::random_access_iterator_tag;
    using value_type = T;
    using difference_type = std::ptrdiff_t;
    using pointer = const T*;
    using reference = const T&;
    const_iterator() = default;
    const_iterator(const ChunkedVector* v, std::size_t i) : v_(v), i_(i) {}
    reference operator*() const { return (*v_)[i_]; }
    pointer operator->() const { return &(*v_)[i_]; }
    reference operator[](difference_type d) const { return (*v_)[i_ + d]; }
    const_iterator& operator++() { return ++i_, *this; }
    const_iterator operator++(int) { auto t = *this; ++i_; return t; }
    const_iterator& operator--() { return --i_, *this; }
    const_iterator operator--(int) { auto t = *this; --i_; return t; }
    const_iterator& operator+=(difference_type d) { return i_ += d, *this; }
    const_iterator& operator-=(difference_type d) { return i_ -= d, *this; }
    const_iterator operator+(difference_type d) const { return {v_, i_ + d}; }
    const_iterator operator-(difference_type d) const { return {v_, i_ - d}; }
    difference_type operator-(const const_iterator& o) const {
      return static_cast<difference_type>(i_) - static_cast<difference_type>(o.i_);
    }
    bool operator==(const const_iterator& o) const { return i_ == o.i_; }
    bool operator!=(const const_iterator& o) const { return i_ != o.i_; }
    bool operator<(const const_iterator& o) const { return i_ < o.i_; }

   private:
    const ChunkedVector* v_ = nullptr;
    std::size_t i_ = 0;
  };
  const_iterator begin() const { return {this, 0}; }
  const_iterator end() const { return {this, size_}; }

  bool operator==(const ChunkedVector& o) const {
    if (size_ != o.size_) return false;
    for (std::size_t c = 0; c < slots_.size(); ++c)
      if (slots_[c].chunk != o.slots_[c].chunk && *slots_[c].chunk != *o.slots_[c].chunk)
        return false;
    return true;
  }
  bool operator!=(const ChunkedVector& o) const { return !(*this == o); }
  bool operator==(const std::vector<T>& o) const {
    if (size_ != o.size()) return false;
    for (std::size_t i = 0; i < size_; ++i)
      if (!((*this)[i] == o[i])) return false;
    return true;
  }
  bool operator!=(const std::vector<T>& o) const { return !(*this == o); }

 private:
  struct Slot {
    std::shared_ptr<std::vector<T>> chunk;
    std::uint64_t epoch;  ///< of the vector that made it; in place only when it is this one's
  };
  std::vector<T>& chunkToEdit(std::size_t c) {
    Slot& s = slots_[c];
    const std::uint64_t epoch = epoch_.get();
    if (s.epoch != epoch) {
      auto copy = std::make_shared<std::vector<T>>();
      copy->reserve(kChunk);
      copy->assign(s.chunk->begin(), s.chunk->end());
      s.chunk = std::move(copy);
      s.epoch = epoch;
    }
    return *s.chunk;
  }

  std::vector<Slot> slots_;
  std::size_t size_ = 0;
  SharingEpoch epoch_;
};

}  // namespace view_selection::core
