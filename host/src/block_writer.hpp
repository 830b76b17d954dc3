// Bytes on their way to a stream, gathered into blocks: the writers of large files (meshes,
// voxel cubes) emit millions of small values, and a stream call per value costs several times
// what formatting it does.
#pragma once

#include <algorithm>
#include <charconv>
#include <cstring>
#include <memory>
#include <ostream>
#include <string>

#include "little_endian.hpp"

namespace oclvox::detail {

// Gathers bytes into blocks of about a megabyte before they reach the stream; flush() writes the
// rest. Made without a stream it keeps every byte in memory instead (data(), size()), its buffer
// growing as needed: so a part of a file can be formatted on one core and written by another.
class BlockWriter {
  public:
    explicit BlockWriter(std::ostream& out)
        : out_(&out), buffer_(new char[kBlock]), capacity_(kBlock) {}
    BlockWriter() = default;

    void bytes(const char* data, size_t size) {
        if (out_ && size > kBlock) {  // too large to gather: straight to the stream
            flush();
            out_->write(data, std::streamsize(size));
            return;
        }
        std::memcpy(room(size), data, size);
        used_ += size;
    }
    void text(const std::string& s) { bytes(s.data(), s.size()); }
    void character(char c) {
        *room(1) = c;
        ++used_;
    }
    template <typename T>
    void little_endian(T value) {
        detail::store_le(room(sizeof(T)), value);
        used_ += sizeof(T);
    }
    // Shortest round-trip decimal text (doubles) or plain decimal (integers), formatted in place.
    template <typename T>
    void number(T value) {
        char* const start = room(kLongestNumber);
        used_ += size_t(std::to_chars(start, start + kLongestNumber, value).ptr - start);
    }
    // Writes the bytes gathered to the stream (nothing without one).
    void flush() {
        if (!out_) return;
        out_->write(buffer_.get(), std::streamsize(used_));
        used_ = 0;
    }

    // The bytes gathered (all of them without a stream), and forgetting them.
    const char* data() const { return buffer_.get(); }
    size_t size() const { return used_; }
    void clear() { used_ = 0; }

  private:
    static constexpr size_t kBlock = size_t(1) << 20;
    static constexpr size_t kLongestNumber = 32;  // "-1.2345678901234567e-308" and any integer

    // Where `size` more bytes go: after a flush to the stream, or in a larger buffer.
    char* room(size_t size) {
        if (used_ + size > capacity_) make_room(size);
        return buffer_.get() + used_;
    }
    void make_room(size_t size) {
        flush();
        if (used_ + size <= capacity_) return;
        const size_t capacity = std::max({2 * capacity_, used_ + size, size_t(4096)});
        std::unique_ptr<char[]> larger(new char[capacity]);
        if (used_) std::memcpy(larger.get(), buffer_.get(), used_);
        buffer_ = std::move(larger);
        capacity_ = capacity;
    }

    std::ostream* out_ = nullptr;
    std::unique_ptr<char[]> buffer_;
    size_t capacity_ = 0;
    size_t used_ = 0;
};

}  // namespace oclvox::detail
