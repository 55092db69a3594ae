// What the Python side checks of a batch of rays before casting them, in one parallel pass
// over the arrays (numpy's reductions, one per question, took a fifth of a cast).
#pragma once

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <thread>
#include <vector>

namespace vrc {

struct RayExtent {
    bool finite = true;                 ///< every origin and direction component is finite
    bool nonzero = true;                ///< every direction has a nonzero component
    double origin_min = HUGE_VAL;       ///< least origin component
    double origin_max = -HUGE_VAL;      ///< greatest origin component
    double longest_min = HUGE_VAL;      ///< least of the directions' largest |components|
    double longest_max = 0;             ///< greatest of them

    void join(const RayExtent& o) {
        finite = finite && o.finite;
        nonzero = nonzero && o.nonzero;
        origin_min = std::min(origin_min, o.origin_min);
        origin_max = std::max(origin_max, o.origin_max);
        longest_min = std::min(longest_min, o.longest_min);
        longest_max = std::max(longest_max, o.longest_max);
    }
};

/// The extent of rays 0 .. n - 1 (origins and directions (n, 3), row-major; with
/// `one_origin`, a single origin row for all).
inline RayExtent ray_extent(const double* origins, const double* directions, std::size_t n, unsigned threads,
                            bool one_origin = false) {
    const std::size_t origin_stride = one_origin ? 0 : 3;
    const unsigned parts = std::max(1u, std::min<unsigned>(threads, unsigned(n / 65536 + 1)));
    std::vector<RayExtent> part(parts);
    auto work = [&](unsigned p) {
        RayExtent e;
        double finite_sum = 0;  // (inf or NaN anywhere makes the sum NaN: one test at the end)
        for (std::size_t i = n * p / parts, end = n * (p + 1) / parts; i < end; ++i) {
            const double* o = origins + origin_stride * i;
            const double* d = directions + 3 * i;
            double longest = 0;
            for (int k = 0; k < 3; ++k) {
                e.origin_min = o[k] < e.origin_min ? o[k] : e.origin_min;
                e.origin_max = o[k] > e.origin_max ? o[k] : e.origin_max;
                const double a = std::fabs(d[k]);
                longest = a > longest ? a : longest;
                finite_sum += o[k] * 0 + d[k] * 0;
            }
            e.longest_min = longest < e.longest_min ? longest : e.longest_min;
            e.longest_max = longest > e.longest_max ? longest : e.longest_max;
        }
        e.finite = finite_sum == 0;
        e.nonzero = !(e.longest_min == 0);
        part[p] = e;
    };
    std::vector<std::thread> workers;
    for (unsigned p = 1; p < parts; ++p) workers.emplace_back(work, p);
    work(0);
    for (auto& w : workers) w.join();
    RayExtent all;
    for (const RayExtent& e : part) all.join(e);
    return all;
}

}  // namespace vrc
