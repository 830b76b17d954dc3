// Welding: numbering equal vertex positions alike, shared by the mesh loader and the closed-mesh
// check (and the winding number's boundary fans).
#pragma once

#include <array>
#include <cstdint>
#include <cstring>
#include <utility>
#include <vector>

namespace oclvox::detail {

// Numbers the distinct positions offered to it, in the order they are first offered; positions
// are equal when their coordinates' bits are, after -0.0 becomes 0.0 (so equal numbers weld, and
// a NaN of an unused vertex welds only with its own bits). An open-addressing hash table sized
// once for the most positions it will be offered: a pass over a mesh's vertices is linear, where
// sorting them was most of the closed-mesh check.
class PositionNumbering {
  public:
    using Position = std::array<double, 3>;

    explicit PositionNumbering(size_t most_positions) {
        size_t capacity = 16;
        while (capacity < 2 * most_positions) capacity *= 2;
        slots_.assign(capacity, kEmpty);
        keys_.reserve(most_positions);
        positions_.reserve(most_positions);
    }

    // The number of p: that of the equal position offered before, else the next free one.
    uint32_t number(const Position& p) {
        const Key key = key_of(p);
        const size_t mask = slots_.size() - 1;
        for (size_t slot = size_t(hash(key)) & mask;; slot = (slot + 1) & mask) {
            uint32_t& id = slots_[slot];
            if (id == kEmpty) {
                id = uint32_t(positions_.size());
                keys_.push_back(key);
                positions_.push_back(p);
                return id;
            }
            if (keys_[id] == key) return id;
        }
    }

    // The positions by number, each as it was first offered (the numbering is done with them).
    std::vector<Position> take_positions() { return std::move(positions_); }

  private:
    using Key = std::array<uint64_t, 3>;
    static constexpr uint32_t kEmpty = ~uint32_t(0);

    static Key key_of(const Position& p) {
        Key key;
        for (int k = 0; k < 3; ++k) {
            const double value = p[k] + 0.0;  // -0.0 and 0.0 are the same place
            std::memcpy(&key[k], &value, sizeof value);
        }
        return key;
    }
    // Mixes every bit of the three coordinates into the low bits the table uses (coordinates on
    // a regular lattice differ only in a few high mantissa bits).
    static uint64_t hash(const Key& key) {
        uint64_t h = 0x9e3779b97f4a7c15ull;
        for (const uint64_t bits : key) {
            h = (h ^ bits) * 0xbf58476d1ce4e5b9ull;
            h ^= h >> 31;
        }
        h *= 0x94d049bb133111ebull;
        return h ^ (h >> 29);
    }

    std::vector<uint32_t> slots_;  // a position's number, or kEmpty
    std::vector<Key> keys_;        // by number
    std::vector<Position> positions_;
};

}  // namespace oclvox::detail
