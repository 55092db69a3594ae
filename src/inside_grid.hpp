// Inside/outside of many points without a ray per point (Scene.contains): a grid of cells
// over the mesh's box. A cell that holds no point of any triangle ("empty") has one answer
// throughout, and so has every empty cell it reaches through empty face neighbours: the
// segment between two such points crosses no triangle. So one exact ray per connected
// region of empty cells classifies them all, and a point in an empty cell is answered by
// a lookup. A point in a cell that triangles touch is answered by the exact crossings of a
// short segment from it to a point of the nearest empty cell, whose answer is known.
//
// Exactness rests on the cells' bounds being those the lookups use: a coordinate's cell is
// floor((x - low) * inv_h) in floating point, monotonic in x, so each cell is an interval
// of the reals per axis and a box in space (convex), and a triangle's points lie in the
// cells of its bounding box's corners and those between. Segment ends sit a third of a
// cell inside theirs, far more than the roundings of the cells' bounds and of the segment's
// direction where the grid is usable (cells wider than 2^-30 of the coordinates).
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <vector>

namespace vrc {

class InsideGrid {
public:
    /// What classify says of a point.
    enum Answer : uint8_t { kOutside = 0, kInside = 1, kSegmentToOutside = 2, kSegmentToInside = 3 };

    /// A grid of cubic cells over the box [low, high] of `points`, about `per_axis` along
    /// its longest side (at most 256); triangles given by point indices.
    InsideGrid(const double* points, const uint32_t* triangles, std::size_t n_triangles,
               const std::array<double, 3>& low, const std::array<double, 3>& high, int per_axis)
        : low_(low), high_(high) {
        const double extent = std::max({high[0] - low[0], high[1] - low[1], high[2] - low[2]});
        inv_h_ = extent > 0 ? std::clamp(per_axis, 1, 256) / extent : 1.0;
        h_ = 1.0 / inv_h_;
        for (int c = 0; c < 3; ++c) n_[c] = axis_cell(high[c], c) + 1;
        label_.assign(std::size_t(n_[0]) * std::size_t(n_[1]) * std::size_t(n_[2]), kUnset);
        mark_triangles(points, triangles, n_triangles);
        label_empty_regions();
        point_to_nearest_empty();
    }

    /// Whether points can be answered by the grid: some cell is empty, and cells are wide
    /// enough against the coordinates' roundings (a box far from the origin for its size
    /// is not) that points placed a third of a cell inside one stay in it.
    bool usable() const {
        const double largest = std::max({std::abs(low_[0]), std::abs(low_[1]), std::abs(low_[2]), std::abs(high_[0]),
                                         std::abs(high_[1]), std::abs(high_[2])});
        return !regions_.empty() && h_ > std::ldexp(largest, -30);
    }

    /// A point of each region of empty cells (its first cell's centre), for the caller to
    /// decide exactly and give back to set_inside.
    std::vector<std::array<double, 3>> region_points() const {
        std::vector<std::array<double, 3>> out;
        for (const int32_t cell : regions_) out.push_back(cell_point(cell, 0.5, 0.5, 0.5));
        return out;
    }

    std::size_t regions() const { return regions_.size(); }

    void set_inside(const uint8_t* inside) { inside_.assign(inside, inside + regions_.size()); }

    /// Per point its Answer; for points that need a segment (answers 2 and 3) the segment's
    /// end, in order, in `ends`. Points must be finite.
    void classify(const double* p, std::size_t n, uint8_t* answers, std::vector<double>& ends) const {
        for (std::size_t i = 0; i < n; ++i, p += 3) {
            if (p[0] < low_[0] || p[1] < low_[1] || p[2] < low_[2] || p[0] > high_[0] || p[1] > high_[1] ||
                p[2] > high_[2]) {
                answers[i] = kOutside;  // beyond the box of every triangle's points
                continue;
            }
            const int32_t label = label_[index(axis_cell(p[0], 0), axis_cell(p[1], 1), axis_cell(p[2], 2))];
            if (label >= 0) {
                answers[i] = inside_[std::size_t(label)];
                continue;
            }
            const int32_t target = -label - 1;
            // Off the centre, at fractions no common mesh aligns with, so the segment is
            // not in the plane of a face of an axis-aligned or diagonal mesh.
            const std::array<double, 3> end = cell_point(target, 0.6378, 0.3284, 0.5913);
            ends.insert(ends.end(), end.begin(), end.end());
            answers[i] = uint8_t(kSegmentToOutside + inside_[std::size_t(label_[std::size_t(target)])]);
        }
    }

private:
    static constexpr int32_t kUnset = INT32_MIN;
    static constexpr int32_t kTouched = INT32_MIN + 1;

    int32_t axis_cell(double x, int c) const { return int32_t(std::floor((x - low_[c]) * inv_h_)); }
    int32_t index(int32_t i, int32_t j, int32_t k) const { return (k * n_[1] + j) * n_[0] + i; }
    int32_t coordinate(int32_t cell, int c) const {
        return c == 0 ? cell % n_[0] : c == 1 ? (cell / n_[0]) % n_[1] : cell / (n_[0] * n_[1]);
    }
    std::array<double, 3> cell_point(int32_t cell, double fx, double fy, double fz) const {
        const double f[3] = {fx, fy, fz};
        std::array<double, 3> q;
        for (int c = 0; c < 3; ++c) q[c] = low_[c] + (double(coordinate(cell, c)) + f[c]) * h_;
        return q;
    }

    void mark_triangles(const double* points, const uint32_t* triangles, std::size_t n_triangles) {
        for (std::size_t t = 0; t < n_triangles; ++t) {
            int32_t lo[3], hi[3];
            for (int c = 0; c < 3; ++c) {
                const double a = points[3 * triangles[3 * t] + c], b = points[3 * triangles[3 * t + 1] + c],
                             d = points[3 * triangles[3 * t + 2] + c];
                lo[c] = axis_cell(std::min({a, b, d}), c);
                hi[c] = axis_cell(std::max({a, b, d}), c);
            }
            for (int32_t k = lo[2]; k <= hi[2]; ++k)
                for (int32_t j = lo[1]; j <= hi[1]; ++j)
                    for (int32_t i = lo[0]; i <= hi[0]; ++i) label_[std::size_t(index(i, j, k))] = kTouched;
        }
    }

    /// The face neighbours of `cell`, passed to `f`.
    template <class F>
    void neighbours(int32_t cell, F&& f) const {
        const int32_t step[3] = {1, n_[0], n_[0] * n_[1]};
        for (int c = 0; c < 3; ++c) {
            const int32_t at = coordinate(cell, c);
            if (at > 0) f(cell - step[c]);
            if (at + 1 < n_[c]) f(cell + step[c]);
        }
    }

    /// Empty cells labelled by region (>= 0), breadth first through empty face neighbours.
    void label_empty_regions() {
        std::vector<int32_t> queue;
        for (int32_t start = 0; start < int32_t(label_.size()); ++start) {
            if (label_[std::size_t(start)] != kUnset) continue;
            const int32_t region = int32_t(regions_.size());
            regions_.push_back(start);
            label_[std::size_t(start)] = region;
            queue.assign(1, start);
            for (std::size_t q = 0; q < queue.size(); ++q)
                neighbours(queue[q], [&](int32_t next) {
                    if (label_[std::size_t(next)] != kUnset) return;
                    label_[std::size_t(next)] = region;
                    queue.push_back(next);
                });
        }
    }

    /// Touched cells labelled -1 - (a nearest empty cell, in face steps), breadth first from
    /// every empty cell at once.
    void point_to_nearest_empty() {
        if (regions_.empty()) return;
        std::vector<int32_t> queue, target(label_.size(), -1);
        for (int32_t cell = 0; cell < int32_t(label_.size()); ++cell)
            if (label_[std::size_t(cell)] >= 0) {
                queue.push_back(cell);
                target[std::size_t(cell)] = cell;
            }
        for (std::size_t q = 0; q < queue.size(); ++q)
            neighbours(queue[q], [&](int32_t next) {
                if (target[std::size_t(next)] >= 0) return;
                target[std::size_t(next)] = target[std::size_t(queue[q])];
                label_[std::size_t(next)] = -1 - target[std::size_t(next)];
                queue.push_back(next);
            });
    }

    std::array<double, 3> low_, high_;
    double inv_h_ = 1, h_ = 1;
    int32_t n_[3] = {1, 1, 1};
    std::vector<int32_t> label_;    ///< per cell: region (empty) or -1 - nearest empty cell (touched)
    std::vector<int32_t> regions_;  ///< each region's first cell
    std::vector<uint8_t> inside_;   ///< per region
};

}  // namespace vrc
