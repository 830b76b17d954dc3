// Bytes on their way to a stream, gathered into blocks: the writers of large files (meshes,
// voxel cubes) emit millions of small values, and a stream call per value costs several times
// what formatting it does.
#pragma once

#include <charconv>
#include <cstring>
#include <memory>
#include <ostream>
#include <string>

#include "little_endian.hpp"

namespace oclvox::detail {

// Gathers bytes into blocks of about a megabyte before they reach the stream; flush() writes the
// rest.
class BlockWriter {
  public:
    explicit BlockWriter(std::ostream& out) : out_(out), buffer_(new char[kCapacity]) {}
    void bytes(const char* data, size_t size) {
        if (used_ + size > kCapacity) flush();
        if (size > kCapacity) {
            out_.write(data, std::streamsize(size));
            return;
        }
        std::memcpy(buffer_.get() + used_, data, size);
        used_ += size;
    }
    void text(const std::string& s) { bytes(s.data(), s.size()); }
    void character(char c) {
        if (used_ == kCapacity) flush();
        buffer_[used_++] = c;
    }
    template <typename T>
    void little_endian(T value) {
        if (used_ + sizeof(T) > kCapacity) flush();
        detail::store_le(buffer_.get() + used_, value);
        used_ += sizeof(T);
    }
    // Shortest round-trip decimal text (doubles) or plain decimal (integers), formatted in place.
    template <typename T>
    void number(T value) {
        if (used_ + kLongestNumber > kCapacity) flush();
        char* const start = buffer_.get() + used_;
        used_ += size_t(std::to_chars(start, start + kLongestNumber, value).ptr - start);
    }
    void flush() {
        out_.write(buffer_.get(), std::streamsize(used_));
        used_ = 0;
    }

  private:
    static constexpr size_t kCapacity = size_t(1) << 20;
    static constexpr size_t kLongestNumber = 32;  // "-1.2345678901234567e-308" and any integer
    std::ostream& out_;
    std::unique_ptr<char[]> buffer_;
    size_t used_ = 0;
};

}  // namespace oclvox::detail
