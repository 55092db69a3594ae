// Rows of several arrays gathered by one list of row indices, on several threads: a scan's
// returns taken from the arrays the cast wrote for every beam (numpy's take runs on one
// thread, and a lidar's returns are ten arrays of a hundred thousand rows).
#pragma once

#include <algorithm>
#include <cstdint>
#include <cstring>
#include <thread>
#include <vector>

namespace vrc {

/// One array's gathering: rows of `row_bytes` bytes from `from` to `to`.
struct RowCopy {
    const char* from;
    char* to;
    std::size_t row_bytes;
};

namespace detail {
/// Row i of `to` is row rows[i] of `from`, for i in [begin, end). kBytes: the row size
/// when known at compile time (then each row is a few moves), else 0.
template <std::size_t kBytes>
void copy_rows(const RowCopy& c, const int64_t* rows, std::size_t begin, std::size_t end) {
    const std::size_t bytes = kBytes != 0 ? kBytes : c.row_bytes;
    for (std::size_t i = begin; i < end; ++i) std::memcpy(c.to + i * bytes, c.from + std::size_t(rows[i]) * bytes, bytes);
}
}  // namespace detail

/// Gathers rows `rows[0 .. n)` (each within its source) of every copy, split among
/// `threads` threads by row.
inline void take_rows(const std::vector<RowCopy>& copies, const int64_t* rows, std::size_t n, unsigned threads) {
    const auto work = [&](std::size_t begin, std::size_t end) {
        for (const RowCopy& c : copies) {
            switch (c.row_bytes) {
                case 1: detail::copy_rows<1>(c, rows, begin, end); break;
                case 4: detail::copy_rows<4>(c, rows, begin, end); break;
                case 8: detail::copy_rows<8>(c, rows, begin, end); break;
                case 12: detail::copy_rows<12>(c, rows, begin, end); break;
                case 24: detail::copy_rows<24>(c, rows, begin, end); break;
                default: detail::copy_rows<0>(c, rows, begin, end);
            }
        }
    };
    // (a thread started costs more than copying a few thousand rows)
    const std::size_t workers = std::clamp<std::size_t>(n / 16384, 1, std::max(1u, threads));
    if (workers == 1) return work(0, n);
    std::vector<std::thread> pool;
    for (std::size_t w = 0; w < workers; ++w) pool.emplace_back(work, n * w / workers, n * (w + 1) / workers);
    for (std::thread& t : pool) t.join();
}

}  // namespace vrc
