// Welding: numbering equal vertex positions alike, shared by the mesh loader and the closed-mesh
// check (and the winding number's boundary fans).
#pragma once

#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <cstdint>
#include <cstring>
#include <vector>

namespace oclvox::detail {

struct NumberedPositions {
    std::vector<uint32_t> numbers;                 // of each offered position, in offering order
    std::vector<std::array<double, 3>> positions;  // by number, each as first offered
};

// Numbers the positions offered, positions[order[i]] for i = 0, 1, ... (positions[i] without an
// order), in the order they are first offered; positions are equal when their coordinates' bits
// are, after -0.0 becomes 0.0 (so equal numbers weld, and a NaN of an unused vertex welds only
// with its own bits). Linear, with the hashing in parallel: the offers are split by the high bits
// of their hash into partitions of a few thousand, each partition finds every offer's first equal
// offer in a hash table of its own (small enough to stay in cache, where one table for a whole
// mesh missed the cache at every probe), and a last pass in offering order hands out the numbers.
inline NumberedPositions number_positions(const std::vector<std::array<double, 3>>& positions,
                                          const std::vector<uint32_t>* order = nullptr) {
    using Key = std::array<uint64_t, 3>;
    const size_t n = order ? order->size() : positions.size();
    auto offered = [&](size_t i) -> const std::array<double, 3>& {
        return positions[order ? (*order)[i] : i];
    };
    auto key_of = [&](size_t i) {
        Key key;
        for (int k = 0; k < 3; ++k) {
            const double value = offered(i)[k] + 0.0;  // -0.0 and 0.0 are the same place
            std::memcpy(&key[k], &value, sizeof value);
        }
        return key;
    };
    constexpr size_t kChunk = 16384;
    const size_t chunks = (n + kChunk - 1) / kChunk;

    // Phase 1: every offer's hash, mixing every bit of the three coordinates into the bits used
    // (coordinates on a regular lattice differ only in a few high mantissa bits).
    std::vector<uint64_t> hashes(n);
    tbb::parallel_for(size_t(0), chunks, [&](size_t c) {
        for (size_t i = c * kChunk; i < std::min(n, (c + 1) * kChunk); ++i) {
            uint64_t h = 0x9e3779b97f4a7c15ull;
            for (const uint64_t bits : key_of(i)) {
                h = (h ^ bits) * 0xbf58476d1ce4e5b9ull;
                h ^= h >> 31;
            }
            h *= 0x94d049bb133111ebull;
            hashes[i] = h ^ (h >> 29);
        }
    });

    // Phase 2: the offers grouped by partition (the hash's top bits), ascending within each: a
    // counting sort.
    int partition_bits = 0;
    while (partition_bits < 16 && (n >> partition_bits) > 4096) ++partition_bits;
    const size_t partitions = size_t(1) << partition_bits;
    auto partition_of = [&](size_t i) {
        return partition_bits ? size_t(hashes[i] >> (64 - partition_bits)) : size_t(0);
    };
    std::vector<uint32_t> first_offer(partitions + 1, 0);
    for (size_t i = 0; i < n; ++i) ++first_offer[partition_of(i) + 1];
    for (size_t p = 0; p < partitions; ++p) first_offer[p + 1] += first_offer[p];
    std::vector<uint32_t> grouped(n);
    {
        std::vector<uint32_t> next(first_offer.begin(), first_offer.end() - 1);
        for (size_t i = 0; i < n; ++i) grouped[next[partition_of(i)]++] = uint32_t(i);
    }

    // Phase 3: per partition, in parallel, each offer's first equal offer, and how many offers
    // are the first of their position.
    std::vector<uint32_t> first_equal(n);
    std::vector<size_t> distinct(partitions, 0);
    constexpr uint32_t kEmpty = ~uint32_t(0);
    tbb::parallel_for(size_t(0), partitions, [&](size_t p) {
        const uint32_t begin = first_offer[p], end = first_offer[p + 1];
        size_t capacity = 16;
        while (capacity < 2 * size_t(end - begin)) capacity *= 2;
        std::vector<uint32_t> slots(capacity, kEmpty);  // the first offer of a key
        const size_t mask = capacity - 1;
        for (uint32_t g = begin; g < end; ++g) {
            const uint32_t i = grouped[g];
            const Key key = key_of(i);
            for (size_t slot = size_t(hashes[i]) & mask;; slot = (slot + 1) & mask) {
                if (slots[slot] == kEmpty) {
                    slots[slot] = i;
                    first_equal[i] = i;
                    ++distinct[p];
                    break;
                }
                const uint32_t j = slots[slot];
                if (hashes[j] == hashes[i] && key_of(j) == key) {
                    first_equal[i] = j;
                    break;
                }
            }
        }
    });

    // Phase 4: numbers in offering order; an offer's first equal offer comes no later.
    NumberedPositions out;
    out.numbers.resize(n);
    size_t positions_out = 0;
    for (const size_t count : distinct) positions_out += count;
    out.positions.reserve(positions_out);  // (growing would copy and fault in each size again)
    for (size_t i = 0; i < n; ++i) {
        if (first_equal[i] == i) {
            out.numbers[i] = uint32_t(out.positions.size());
            out.positions.push_back(offered(i));
        } else {
            out.numbers[i] = out.numbers[first_equal[i]];
        }
    }
    return out;
}

}  // namespace oclvox::detail
