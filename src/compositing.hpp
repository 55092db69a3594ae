// The per-pixel passes of compositing an image cast in pieces on MPI ranks
// (vtkraycast/parallel.py moves the buffers): every rank's hits travel as records to the
// rank deciding their block of the frame, which flags each record won or lost; the
// winners' rows then travel to the ranks receiving the image. Only hit pixels travel, so
// the bytes moved follow the hits, not the frame (the design of sort-last compositing with
// sparse images; Moreland et al., "An image compositing solution at scale", SC 2011).
#pragma once

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <limits>
#include <type_traits>
#include <stdexcept>
#include <vector>

namespace vrc::compositing {

/// One hit sent to the rank deciding its pixel: the pixel's place in that rank's block,
/// the depth and the triangle's global key (packed: these bytes are what travels).
#pragma pack(push, 1)
struct HitRecord {
    uint32_t offset;
    double depth;
    int64_t key;
};
#pragma pack(pop)
static_assert(sizeof(HitRecord) == 20);

/// The records of the hits of one rank's image (`hit` nonzero at hit pixels: the
/// vtkValidPointMask, an eighth of TriangleId's bytes to scan) into `out` (room for one
/// per pixel), grouped by the block deciding them (block b: pixels starts[b] ..
/// starts[b + 1] - 1, consecutive, in pixel order). counts[b] receives the number of
/// records for block b; returns the number of records.
template <class Depth>
std::size_t hit_records(const uint8_t* hit, const int64_t* triangle, const Depth* depth, const int64_t* keys,
                        std::size_t triangles, const int64_t* starts, std::size_t blocks, int64_t* counts,
                        HitRecord* out) {
    std::size_t k = 0;
    for (std::size_t b = 0; b < blocks; ++b) {
        const std::size_t begin = k;
        int64_t i = starts[b];
        const int64_t end = starts[b + 1];
        while (i < end) {
            uint64_t eight;  // (eight pixels at a time: a frame is mostly runs of misses or hits)
            if (i + 8 <= end && (std::memcpy(&eight, hit + i, 8), eight == 0)) {
                i += 8;
                continue;
            }
            if (hit[i]) out[k++] = {uint32_t(i - starts[b]), double(depth[i]), triangle[i]};
            ++i;
        }
        counts[b] = int64_t(k - begin);
    }
    // The keys in a pass of their own: its loads do not wait on the scan's branches, and the
    // keys of the records ahead are fetched while this one's arrives.
    constexpr std::size_t kAhead = 16;
    for (std::size_t r = 0; r < k; ++r) {
        if (r + kAhead < k && uint64_t(out[r + kAhead].key) < triangles) __builtin_prefetch(keys + out[r + kAhead].key);
        const int64_t t = out[r].key;
        if (uint64_t(t) >= triangles) throw std::invalid_argument("a hit pixel without a hit triangle");
        out[r].key = keys[t];
    }
    return k;
}

/// Which records win their pixel: the least depth, and among the hits within the tie
/// tolerance of it (the same point reached through two triangles) the lowest key, as the
/// serial cast decides. `records` hold every rank's hits of one block of `pixels` pixels.
/// `best`: room for one per pixel of the block; only the pixels some record names are
/// touched (a block mostly empty costs nothing).
struct Best {
    double depth;
    int64_t key;
};
inline void resolve(const HitRecord* records, std::size_t n, double tie, Best* best, uint8_t* won) {
    for (std::size_t i = 0; i < n; ++i) best[records[i].offset] = {HUGE_VAL, std::numeric_limits<int64_t>::max()};
    for (std::size_t i = 0; i < n; ++i) {
        Best& b = best[records[i].offset];
        b.depth = records[i].depth < b.depth ? records[i].depth : b.depth;
    }
    auto candidate = [&](const HitRecord& r) {
        const double nearest = best[r.offset].depth;
        return r.depth <= nearest + tie * std::fabs(nearest);
    };
    for (std::size_t i = 0; i < n; ++i) {
        Best& b = best[records[i].offset];
        if (candidate(records[i]) && records[i].key < b.key) b.key = records[i].key;
    }
    for (std::size_t i = 0; i < n; ++i) won[i] = candidate(records[i]) && records[i].key == best[records[i].offset].key;
}

/// The pixels (ascending) of the records this rank sent that came back flagged won.
class WonPixels {
   public:
    WonPixels(const HitRecord* records, const int64_t* counts, const int64_t* starts, std::size_t blocks,
              const uint8_t* won)
        : records_(records), counts_(counts), starts_(starts), blocks_(blocks), won_(won) {}
    template <class F>
    void each(F&& f) const {
        std::size_t i = 0;
        for (std::size_t b = 0; b < blocks_; ++b)
            for (int64_t k = 0; k < counts_[b]; ++k, ++i)
                if (won_[i]) f(starts_[b] + int64_t(records_[i].offset));
    }

   private:
    const HitRecord* records_;
    const int64_t *counts_, *starts_;
    std::size_t blocks_;
    const uint8_t* won_;
};

/// An array's rows as bytes: `rows` rows of `width` bytes.
struct Rows {
    uint8_t* data;
    std::size_t rows, width;
};

/// Copies n rows of `width` bytes, row from(k) of `source` to row to(k) of `target` for
/// k = 0 .. n - 1, calling ahead(k) first (to fetch a later row). The common widths get a
/// loop of their own, whose fixed-size copies the compiler turns into a few moves.
template <class From, class To, class Ahead>
void copy_rows(std::size_t width, const uint8_t* source, uint8_t* target, std::size_t n, From from, To to,
               Ahead ahead) {
    auto loop = [&](auto fixed) {
        constexpr std::size_t kWidth = decltype(fixed)::value;
        const std::size_t w = kWidth ? kWidth : width;
        for (std::size_t k = 0; k < n; ++k) {
            ahead(k);
            std::memcpy(target + to(k) * w, source + from(k) * w, w);
        }
    };
    switch (width) {
        case 1: return loop(std::integral_constant<std::size_t, 1>{});
        case 4: return loop(std::integral_constant<std::size_t, 4>{});
        case 8: return loop(std::integral_constant<std::size_t, 8>{});
        case 12: return loop(std::integral_constant<std::size_t, 12>{});
        case 16: return loop(std::integral_constant<std::size_t, 16>{});
        case 24: return loop(std::integral_constant<std::size_t, 24>{});
        default: return loop(std::integral_constant<std::size_t, 0>{});
    }
}

/// A rectangle of the frame a rank receives, columns x0 .. x1 and rows y0 .. y1
/// (inclusive, as VTK's extents), on a frame `width` pixels wide; x0 > x1 when it receives
/// nothing.
class Region {
   public:
    Region(int64_t x0, int64_t x1, int64_t y0, int64_t y1, int64_t width)
        : x0_(x0), x1_(x1), width_(width), first_(y0 * width), end_((y1 + 1) * width),
          rows_whole_(x0 == 0 && x1 == width - 1) {
        if (x0 > x1 || y0 > y1) first_ = end_ = 0;
    }
    /// Whether pixel p lies in the region; its place there, row by row, in `place`.
    bool find(int64_t p, std::size_t& place) const {
        if (p < first_ || p >= end_) return false;
        if (rows_whole_) {  // (ParaView's blocks of whole rows and the whole frame: no division)
            place = std::size_t(p - first_);
            return true;
        }
        const int64_t y = (p - first_) / width_, x = (p - first_) - y * width_;
        if (x < x0_ || x > x1_) return false;
        place = std::size_t(y * (x1_ - x0_ + 1) + (x - x0_));
        return true;
    }

   private:
    int64_t x0_, x1_, width_, first_, end_;
    bool rows_whole_;
};

/// Bytes of one row sent: its place in the receiver's region, then one row per array.
inline std::size_t message_row_bytes(const std::vector<Rows>& arrays) {
    std::size_t bytes = sizeof(uint32_t);
    for (const Rows& a : arrays) bytes += a.width;
    return bytes;
}

/// Rows scattered over a frame are a cache miss each (a rank's hits interleave with the
/// others'): the copies fetch this many rows ahead.
constexpr std::size_t kRowsAhead = 64;

/// The rows of the pixels this rank won for each receiving region into `out` (`room`
/// bytes), one message after the other: the places in the region (uint32), then each
/// array's rows. bytes[r] receives the size of region r's message.
inline void winner_rows(const WonPixels& won, const std::vector<Region>& regions, const std::vector<Rows>& arrays,
                        uint8_t* out, std::size_t room, int64_t* bytes) {
    const std::size_t row_bytes = message_row_bytes(arrays);
    std::vector<int64_t> pixels;
    std::vector<uint32_t> places;
    uint8_t* message = out;
    for (std::size_t r = 0; r < regions.size(); ++r) {
        pixels.clear();
        places.clear();
        won.each([&](int64_t p) {
            std::size_t place;
            if (!regions[r].find(p, place)) return;
            pixels.push_back(p);
            places.push_back(uint32_t(place));
        });
        const std::size_t n = pixels.size();
        bytes[r] = int64_t(n * row_bytes);
        if (std::size_t(message - out) + n * row_bytes > room) throw std::invalid_argument("no room for the winners' rows");
        std::memcpy(message, places.data(), n * sizeof(uint32_t));
        uint8_t* rows = message + n * sizeof(uint32_t);
        for (const Rows& a : arrays) {
            copy_rows(
                a.width, a.data, rows, n, [&](std::size_t k) { return std::size_t(pixels[k]); },
                [](std::size_t k) { return k; },
                [&](std::size_t k) {
                    if (k + kRowsAhead < n) __builtin_prefetch(a.data + std::size_t(pixels[k + kRowsAhead]) * a.width);
                });
            rows += n * a.width;
        }
        message += n * row_bytes;
    }
}

/// Writes received messages (as winner_rows made them, one after the other, sizes in
/// `bytes`) into this rank's region arrays.
inline void write_rows(const uint8_t* messages, const int64_t* bytes, std::size_t senders,
                       const std::vector<Rows>& arrays) {
    const std::size_t row_bytes = message_row_bytes(arrays);
    std::vector<uint32_t> places;
    for (std::size_t s = 0; s < senders; ++s) {
        if (bytes[s] % int64_t(row_bytes) != 0) throw std::runtime_error("a compositing message of the wrong size");
        const std::size_t n = std::size_t(bytes[s]) / row_bytes;
        places.resize(n);
        std::memcpy(places.data(), messages, n * sizeof(uint32_t));
        for (uint32_t place : places)
            for (const Rows& a : arrays)
                if (place >= a.rows) throw std::runtime_error("a compositing message names a pixel outside the region");
        const uint8_t* rows = messages + n * sizeof(uint32_t);
        for (const Rows& a : arrays) {
            copy_rows(
                a.width, rows, a.data, n, [](std::size_t k) { return k; },
                [&](std::size_t k) { return std::size_t(places[k]); },
                [&](std::size_t k) {
                    if (k + kRowsAhead < n) __builtin_prefetch(a.data + std::size_t(places[k + kRowsAhead]) * a.width, 1);
                });
            rows += n * a.width;
        }
        messages += bytes[s];
    }
}

}  // namespace vrc::compositing
