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

namespace position_numbering {

// A position's coordinates as bits, after -0.0 becomes 0.0 (the same place): equal keys are equal
// positions, and a NaN of an unused vertex equals only its own bits.
using Key = std::array<uint64_t, 3>;
inline Key key_of(const std::array<double, 3>& position) {
    Key key;
    for (int k = 0; k < 3; ++k) {
        const double value = position[k] + 0.0;
        std::memcpy(&key[k], &value, sizeof value);
    }
    return key;
}

// Mixes every bit of the three coordinates into the bits used (coordinates on a regular lattice
// differ only in a few high mantissa bits).
inline uint64_t hash_of(const Key& key) {
    uint64_t h = 0x9e3779b97f4a7c15ull;
    for (const uint64_t bits : key) {
        h = (h ^ bits) * 0xbf58476d1ce4e5b9ull;
        h ^= h >> 31;
    }
    h *= 0x94d049bb133111ebull;
    return h ^ (h >> 29);
}

constexpr uint32_t kEmpty = ~uint32_t(0);

// The first offer equal to each of offers 0 .. n-1 (offered(i) is offer i's position), and the
// number of distinct positions among them. The offers are split by the high bits of their hash
// into partitions of a few thousand, and each partition finds every offer's first equal offer in
// a hash table of its own (small enough to stay in cache, where one table for all offers missed
// the cache at every probe).
template <class Offered>
std::vector<uint32_t> first_equal_offers(size_t n, const Offered& offered, size_t* distinct_count) {
    // Phase 1: every offer's hash, in parallel.
    constexpr size_t kChunk = 16384;
    const size_t chunks = (n + kChunk - 1) / kChunk;
    std::vector<uint64_t> hashes(n);
    tbb::parallel_for(size_t(0), chunks, [&](size_t c) {
        for (size_t i = c * kChunk; i < std::min(n, (c + 1) * kChunk); ++i)
            hashes[i] = hash_of(key_of(offered(i)));
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
    tbb::parallel_for(size_t(0), partitions, [&](size_t p) {
        const uint32_t begin = first_offer[p], end = first_offer[p + 1];
        size_t capacity = 16;
        while (capacity < 2 * size_t(end - begin)) capacity *= 2;
        std::vector<uint32_t> slots(capacity, kEmpty);  // the first offer of a key
        const size_t mask = capacity - 1;
        for (uint32_t g = begin; g < end; ++g) {
            const uint32_t i = grouped[g];
            const Key key = key_of(offered(i));
            for (size_t slot = size_t(hashes[i]) & mask;; slot = (slot + 1) & mask) {
                if (slots[slot] == kEmpty) {
                    slots[slot] = i;
                    first_equal[i] = i;
                    ++distinct[p];
                    break;
                }
                const uint32_t j = slots[slot];
                if (hashes[j] == hashes[i] && key_of(offered(j)) == key) {
                    first_equal[i] = j;
                    break;
                }
            }
        }
    });
    *distinct_count = 0;
    for (const size_t count : distinct) *distinct_count += count;
    return first_equal;
}

// Offers are first welded within windows of this many consecutive ones.
constexpr size_t kWindow = 32768;

// Within window w of the offers, each offer's first equal offer (in the window) written to
// first_in_window; returns how many are the first of their position there. The window's offers
// are read in order and its table stays in cache.
template <class Offered>
uint32_t weld_window(size_t n, const Offered& offered, size_t w,
                     std::vector<uint32_t>& first_in_window) {
    constexpr size_t kSlots = 2 * kWindow;
    std::vector<uint32_t> slots(kSlots, kEmpty);
    uint32_t firsts = 0;
    for (size_t i = w * kWindow; i < std::min(n, (w + 1) * kWindow); ++i) {
        const Key key = key_of(offered(i));
        for (size_t slot = size_t(hash_of(key)) & (kSlots - 1);; slot = (slot + 1) & (kSlots - 1)) {
            const uint32_t j = slots[slot];
            if (j == kEmpty) {
                slots[slot] = uint32_t(i);
                first_in_window[i] = uint32_t(i);
                ++firsts;
                break;
            }
            if (key_of(offered(j)) == key) {
                first_in_window[i] = j;
                break;
            }
        }
    }
    return firsts;
}

}  // namespace position_numbering

// Numbers the positions offered, positions[order[i]] for i = 0, 1, ... (positions[i] without an
// order), in the order they are first offered; positions are equal when their coordinates' bits
// are, after -0.0 becomes 0.0 (so equal numbers weld, and a NaN of an unused vertex welds only
// with its own bits). Linear, in parallel.
inline NumberedPositions number_positions(const std::vector<std::array<double, 3>>& positions,
                                          const std::vector<uint32_t>* order = nullptr) {
    using namespace position_numbering;
    const size_t n = order ? order->size() : positions.size();
    auto offered = [&](size_t i) -> const std::array<double, 3>& {
        return positions[order ? (*order)[i] : i];
    };
    NumberedPositions out;
    out.numbers.resize(n);

    // Phase 1: equal positions within windows of consecutive offers, where a mesh's repeats
    // mostly lie (an STL's corners: every position about six times, by facets that are neighbours
    // in the file too). Reading the offers in order, this leaves the global pass below a fifth of
    // STL corners to find among the whole mesh's, at random places (buildings as STL: welding 38
    // -> 24 ms). Taken only when the first window shows a quarter of its offers repeat: a mesh of
    // shared vertices (OBJ, PLY) or of shuffled facets would pay the pass for nothing.
    const size_t windows = (n + kWindow - 1) / kWindow;
    std::vector<uint32_t> first_in_window;
    std::vector<uint32_t> window_firsts;  // offers first in their window, window after window
    std::vector<size_t> window_first_at(windows + 1, 0);
    if (windows > 1) {
        first_in_window.resize(n);
        window_first_at[1] = weld_window(n, offered, 0, first_in_window);
        if (window_first_at[1] > kWindow / 4 * 3) first_in_window.clear();
    }
    if (!first_in_window.empty()) {
        tbb::parallel_for(size_t(1), windows, [&](size_t w) {
            window_first_at[w + 1] = weld_window(n, offered, w, first_in_window);
        });
        for (size_t w = 0; w < windows; ++w) window_first_at[w + 1] += window_first_at[w];
        window_firsts.resize(window_first_at[windows]);
        tbb::parallel_for(size_t(0), windows, [&](size_t w) {
            size_t at = window_first_at[w];
            for (size_t i = w * kWindow; i < std::min(n, (w + 1) * kWindow); ++i)
                if (first_in_window[i] == i) window_firsts[at++] = uint32_t(i);
        });
    }
    const bool windowed = !first_in_window.empty();

    // Phase 2: the first equal offer of each offer (or each window's first offers) among all.
    size_t distinct = 0;
    const std::vector<uint32_t> first_equal =
        windowed ? first_equal_offers(
                       window_firsts.size(),
                       [&](size_t r) -> const std::array<double, 3>& {
                           return offered(window_firsts[r]);
                       },
                       &distinct)
                 : first_equal_offers(n, offered, &distinct);

    // Phase 3: numbers in offering order; an offer's first equal offer comes no later.
    out.positions.reserve(distinct);  // (growing would copy and fault in each size again)
    const size_t firsts = windowed ? window_firsts.size() : n;
    std::vector<uint32_t> first_numbers(windowed ? firsts : 0);
    std::vector<uint32_t>& numbers = windowed ? first_numbers : out.numbers;
    for (size_t r = 0; r < firsts; ++r) {
        if (first_equal[r] == r) {
            numbers[r] = uint32_t(out.positions.size());
            out.positions.push_back(offered(windowed ? window_firsts[r] : r));
        } else {
            numbers[r] = numbers[first_equal[r]];
        }
    }
    if (windowed)  // each window's offers: the number of their first in the window
        tbb::parallel_for(size_t(0), windows, [&](size_t w) {
            size_t rank = window_first_at[w];
            const size_t end = std::min(n, (w + 1) * kWindow);
            for (size_t i = w * kWindow; i < end; ++i)
                if (first_in_window[i] == i) out.numbers[i] = first_numbers[rank++];
            for (size_t i = w * kWindow; i < end; ++i)
                out.numbers[i] = out.numbers[first_in_window[i]];
        });
    return out;
}

}  // namespace oclvox::detail
