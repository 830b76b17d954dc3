// OpenCL C helpers shared by kernels that number their work items pair by pair: a prefix array
// of each pair's first item lets an item find its pair by binary search, so a pair with many
// items (a huge triangle) spreads over many work items instead of serialising on one.
#ifndef OCLVOX_WORK_ITEMS_H
#define OCLVOX_WORK_ITEMS_H

// Largest p with first_item[p] <= item (first_item is non-decreasing, first_item[0] == 0).
static uint find_pair(__global const uint* first_item, uint pair_count, uint item) {
    uint lo = 0, hi = pair_count - 1;
    while (lo < hi) {
        uint mid = lo + (hi - lo + 1) / 2;
        if (first_item[mid] <= item)
            lo = mid;
        else
            hi = mid - 1;
    }
    return lo;
}

#endif  // OCLVOX_WORK_ITEMS_H
