// The per-pixel passes of compositing an image cast in pieces on MPI ranks
// (vtkraycast/parallel.py moves the bytes). Direct send: every rank sends each of its hits
// (depth, the triangle's global key, its output rows) to the ranks whose region of the
// image holds the pixel; each receiver keeps, per pixel, the hit the serial cast would
// keep. One exchange, and the bytes moved follow the covered pixels, not the frame (the
// direct-send scheme of sort-last compositing, on sparse images; Moreland et al., "An image
// compositing solution at scale", SC 2011). When the ranks share a node and the whole image
// goes to one of them, it reads the others' full frames where they were cast instead
// (merge_frames; vtkraycast/shared_frames.py).
#pragma once

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <limits>
#include <stdexcept>
#include <type_traits>
#include <vector>

#include "memory.hpp"

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

namespace vrc::compositing {

/// An array's rows as bytes: `rows` rows of `width` bytes.
struct Rows {
    uint8_t* data;
    std::size_t rows, width;
};

/// The hits of one rank's full-frame image: the vtkValidPointMask (an eighth of
/// TriangleId's bytes to scan), TriangleId, Depth, and the global key of each triangle.
template <class Depth>
struct Hits {
    const uint8_t* hit;
    const int64_t* triangle;
    const Depth* depth;
    std::size_t pixels;
    const int64_t* keys;
    std::size_t triangles;

    int64_t key(int64_t p) const {
        const int64_t t = triangle[p];
        if (uint64_t(t) >= triangles) throw std::invalid_argument("a hit pixel without a hit triangle");
        return keys[t];
    }
};

/// What travels ahead of a hit's rows: its place in the receiver's region, its depth and
/// its triangle's key (packed: these bytes are what moves).
#pragma pack(push, 1)
struct HitRecord {
    uint32_t place;
    double depth;
    int64_t key;
};
#pragma pack(pop)
static_assert(sizeof(HitRecord) == 20);

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
    int64_t first() const { return first_; }
    int64_t end() const { return end_; }

   private:
    int64_t x0_, x1_, width_, first_, end_;
    bool rows_whole_;
};

/// Rows scattered over a frame are a cache miss each (a rank's hits interleave with the
/// others'): the copies fetch this many rows ahead.
constexpr std::size_t kRowsAhead = 64;

/// Which rows a copy fetches ahead: those it reads, those it writes, or both.
enum Fetch : unsigned { kFetchSource = 1, kFetchTarget = 2 };

/// Copies n rows of `width` bytes, row from(k) of `source` to row to(k) of `target` for
/// k = 0 .. n - 1, fetching the rows `fetch` names kRowsAhead rows ahead first. The
/// common widths get a loop of their own, whose fixed-size copies the compiler turns into
/// a few moves.
template <class From, class To>
void copy_rows(std::size_t width, const uint8_t* source, uint8_t* target, std::size_t n, From from, To to,
               unsigned fetch) {
    auto loop = [&](auto fixed) {
        constexpr std::size_t kWidth = decltype(fixed)::value;
        const std::size_t w = kWidth ? kWidth : width;
        for (std::size_t k = 0; k < n; ++k) {
            if (k + kRowsAhead < n) {
                if (fetch & kFetchTarget) __builtin_prefetch(target + to(k + kRowsAhead) * w, 1);
                if (fetch & kFetchSource) prefetch_line(source + from(k + kRowsAhead) * w);
            }
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

/// Bytes of one hit sent: its record, then one row per array.
inline std::size_t message_row_bytes(const std::vector<Rows>& arrays) {
    std::size_t bytes = sizeof(HitRecord);
    for (const Rows& a : arrays) bytes += a.width;
    return bytes;
}

/// The hit pixels of [first, end), ascending, appended to `pixels`. Sixteen pixels a step
/// (the mask is mostly zeros: a frame's misses, or the other ranks' hits), each hit a set
/// bit of a compare's byte mask: no branch per pixel.
inline void hit_pixels(const uint8_t* hit, int64_t first, int64_t end, std::vector<int64_t>& pixels) {
    int64_t i = first;
#if defined(__SSE2__)
    for (; i + 16 <= end; i += 16) {
        const __m128i bytes = _mm_loadu_si128(reinterpret_cast<const __m128i*>(hit + i));
        unsigned set = ~unsigned(_mm_movemask_epi8(_mm_cmpeq_epi8(bytes, _mm_setzero_si128()))) & 0xffffu;
        for (; set; set &= set - 1) pixels.push_back(i + __builtin_ctz(set));
    }
#endif
    for (; i < end; ++i)
        if (hit[i]) pixels.push_back(i);
}

/// Every hit of `hits` in each receiving region, into `out` (`room` bytes), one message
/// after the other: n records, then each array's n rows. bytes[r] receives the size of
/// region r's message.
template <class Depth>
void send_hits(const Hits<Depth>& hits, const std::vector<Region>& regions, const std::vector<Rows>& arrays,
               uint8_t* out, std::size_t room, int64_t* bytes) {
    const std::size_t row_bytes = message_row_bytes(arrays);
    std::vector<int64_t> pixels;
    uint8_t* message = out;
    for (std::size_t r = 0; r < regions.size(); ++r) {
        pixels.clear();
        hit_pixels(hits.hit, regions[r].first(), regions[r].end(), pixels);
        std::size_t n = 0, place;
        for (int64_t p : pixels)
            if (regions[r].find(p, place)) pixels[n++] = p;  // (a region narrower than the frame: its columns)
        pixels.resize(n);
        bytes[r] = int64_t(n * row_bytes);
        if (std::size_t(message - out) + n * row_bytes > room) throw std::invalid_argument("no room for the hits");
        uint8_t* records = message;  // (messages follow each other unaligned: records copied bytewise)
        for (std::size_t k = 0; k < n; ++k) {
            // (in two stages: a hit's triangle and depth, then, once they are in, its key)
            if (k + 2 * kRowsAhead < n) {
                prefetch_line(hits.triangle + pixels[k + 2 * kRowsAhead]);
                prefetch_line(hits.depth + pixels[k + 2 * kRowsAhead]);
            }
            if (k + kRowsAhead < n) prefetch_line(hits.keys + hits.triangle[pixels[k + kRowsAhead]]);
            regions[r].find(pixels[k], place);
            const HitRecord record{uint32_t(place), double(hits.depth[pixels[k]]), hits.key(pixels[k])};
            std::memcpy(records + k * sizeof(HitRecord), &record, sizeof(HitRecord));
        }
        uint8_t* rows = message + n * sizeof(HitRecord);
        for (const Rows& a : arrays) {
            copy_rows(
                a.width, a.data, rows, n, [&](std::size_t k) { return std::size_t(pixels[k]); },
                [](std::size_t k) { return k; }, kFetchSource);
            rows += n * a.width;
        }
        message += n * row_bytes;
    }
}

/// Whether a hit at `depth` is within the tie tolerance of the nearest hit's depth.
inline bool is_candidate(double depth, double nearest, double tie) {
    return depth <= nearest + tie * std::fabs(nearest);
}

/// The serial cast's rule at one pixel: of own hit (when `mine`, at `own_depth`) and the
/// others' (`n` depths, in rank order), the least depth wins, and among the hits within
/// the tie tolerance of it (the same point reached through two triangles) the lowest key,
/// own first on equal keys (a triangle two ranks hold), then the first in order. Keys are
/// asked for only where two hits tie. Returns the winning other's index, -1 when own hit
/// wins or there is none.
template <class OwnKey, class Key>
[[gnu::always_inline]] inline int pick_winner(bool mine, double own_depth, const double* depths, std::size_t n,
                                              double tie, OwnKey own_key, Key key) {
    double nearest = mine ? own_depth : HUGE_VAL;
    for (std::size_t k = 0; k < n; ++k) nearest = std::min(nearest, depths[k]);
    const bool own_candidate = mine && is_candidate(own_depth, nearest, tie);
    std::size_t candidates = own_candidate;
    for (std::size_t k = 0; k < n; ++k) candidates += is_candidate(depths[k], nearest, tie);
    int winner = -1;
    if (candidates == 1 && !own_candidate) {
        for (std::size_t k = 0; k < n; ++k)
            if (is_candidate(depths[k], nearest, tie)) winner = int(k);
    } else if (candidates > 1) {
        int64_t least = own_candidate ? own_key() : std::numeric_limits<int64_t>::max();
        for (std::size_t k = 0; k < n; ++k)
            if (is_candidate(depths[k], nearest, tie) && key(k) < least) least = key(k), winner = int(k);
    }
    return winner;
}

/// pick_winner with one other hit at the pixel: whether it wins.
template <class OwnKey, class Key>
[[gnu::always_inline]] inline bool other_wins(bool mine, double own_depth, double depth, double tie, OwnKey own_key,
                                              Key key) {
    if (!mine) return true;
    const double nearest = std::min(own_depth, depth);
    return is_candidate(depth, nearest, tie) && (!is_candidate(own_depth, nearest, tie) || key() < own_key());
}

/// The receiver's side: keeps, for every pixel that received hits (`messages`, as
/// send_hits made them, sizes in `bytes`), the hit the serial cast keeps: the least depth,
/// and among the hits within the tie tolerance of it (the same point reached through two
/// triangles) the lowest key, looked at only where two hits tie. `own`: this rank's own
/// hits in the region, already in the region arrays (a region of whole rows is a slice of
/// its full-frame arrays), or null. Winning received hits' rows are written into `arrays`, their depth into
/// `depth_out` (Depth's rows, or null) and 1 into `mask_out` (or null).
///
/// Each sender's hits come in ascending places, so the senders' streams are merged and
/// every pixel decided once, in one pass, without a per-pixel scratch array. The merge
/// looks at every sender with hits left: cheap when few ranks send to a region (two, or a
/// piece's few neighbours in ParaView's layout).
template <class Depth>
void receive_hits(const uint8_t* messages, const int64_t* bytes, std::size_t senders, const Hits<Depth>* own,
                  double tie, const std::vector<Rows>& arrays, Depth* depth_out, uint8_t* mask_out,
                  std::size_t pixels) {
    struct Stream {
        const uint8_t* message;
        std::size_t n, next = 0;
        HitRecord head;
        std::vector<uint32_t> places;  ///< where its winners go
        std::vector<std::size_t> from;  ///< which of its hits they are
        bool load() {  // (records unaligned in the message: copied out)
            if (next >= n) return false;
            const uint32_t last = next ? head.place : 0;
            std::memcpy(&head, message + next * sizeof(HitRecord), sizeof(HitRecord));
            if (next && head.place <= last) throw std::runtime_error("a compositing message out of order");
            return true;
        }
    };
    const std::size_t row_bytes = message_row_bytes(arrays);
    std::vector<Stream> streams(senders);
    std::vector<Stream*> active;
    const uint8_t* message = messages;
    for (std::size_t s = 0; s < senders; ++s) {
        if (bytes[s] % int64_t(row_bytes) != 0) throw std::runtime_error("a compositing message of the wrong size");
        streams[s].message = message;
        streams[s].n = std::size_t(bytes[s]) / row_bytes;
        if (streams[s].load()) active.push_back(&streams[s]);
        message += bytes[s];
    }
    if (active.size() == 1) {  // one sender (the whole image on one rank from two): no merge
        Stream& s = *active.front();
        for (;;) {
            const uint32_t place = s.head.place;
            if (place >= pixels) throw std::runtime_error("a compositing message names a pixel outside the region");
            if (own && s.next + kRowsAhead < s.n) {  // (own's rows at the places ahead: a cache miss each)
                uint32_t ahead;
                std::memcpy(&ahead, s.message + (s.next + kRowsAhead) * sizeof(HitRecord), sizeof ahead);
                prefetch_line(own->hit + ahead);
                prefetch_line(own->depth + ahead);
            }
            const bool mine = own && own->hit[place];
            if (other_wins(
                    mine, mine ? double(own->depth[place]) : 0.0, s.head.depth, tie,
                    [&] { return own->key(int64_t(place)); }, [&] { return s.head.key; })) {
                s.places.push_back(place);
                s.from.push_back(s.next);
                if (depth_out) depth_out[place] = Depth(s.head.depth);
                if (mask_out) mask_out[place] = 1;
            }
            ++s.next;
            if (!s.load()) break;
        }
        active.clear();
    }
    std::vector<Stream*> group;
    std::vector<double> depths;
    while (!active.empty()) {
        uint32_t place = active.front()->head.place;
        for (const Stream* s : active) place = std::min(place, s->head.place);
        if (place >= pixels) throw std::runtime_error("a compositing message names a pixel outside the region");
        group.clear();
        for (Stream* s : active)
            if (s->head.place == place) group.push_back(s);
        const bool mine = own && own->hit[place];
        depths.clear();
        for (const Stream* s : group) depths.push_back(s->head.depth);
        const int w = pick_winner(
            mine, mine ? double(own->depth[place]) : 0.0, depths.data(), group.size(), tie,
            [&] { return own->key(int64_t(place)); }, [&](std::size_t k) { return group[k]->head.key; });
        Stream* winner = w < 0 ? nullptr : group[std::size_t(w)];
        if (winner) {
            winner->places.push_back(place);
            winner->from.push_back(winner->next);
            if (depth_out) depth_out[place] = Depth(winner->head.depth);
            if (mask_out) mask_out[place] = 1;
        }
        for (Stream* s : group) {
            ++s->next;
            if (!s->load()) active.erase(std::find(active.begin(), active.end(), s));
        }
    }
    // The region arrays may be own's: every read of own's hits is done.
    for (Stream& s : streams) {
        const uint8_t* rows = s.message + s.n * sizeof(HitRecord);
        for (const Rows& a : arrays) {
            copy_rows(
                a.width, rows, a.data, s.places.size(), [&](std::size_t k) { return s.from[k]; },
                [&](std::size_t k) { return std::size_t(s.places[k]); }, kFetchTarget);
            rows += s.n * a.width;
        }
    }
}

/// Another rank's full-frame image, read where it lies (memory the ranks of a node share):
/// its hits and the rows of its other output arrays, in the receiver's order.
template <class Depth>
struct Frame {
    Hits<Depth> hits;
    std::vector<Rows> rows;
};

/// The pixels [0, pixels) where any of `masks` is set, ascending.
inline void any_hit_pixels(const std::vector<const uint8_t*>& masks, std::size_t pixels, std::vector<int64_t>& out) {
    if (masks.size() == 1) return hit_pixels(masks[0], 0, int64_t(pixels), out);
    std::vector<uint8_t> any(pixels, 0);  // (more than two ranks on a node: their masks joined first)
    for (const uint8_t* mask : masks)
        for (std::size_t p = 0; p < pixels; ++p) any[p] |= mask[p];
    hit_pixels(any.data(), 0, int64_t(pixels), out);
}

/// The whole image on one rank of a node, from the other ranks' full-frame images in shared
/// memory (no message: nothing is gathered or moved but the winners' rows): keeps, per
/// pixel, the hit the serial cast keeps (pick_winner) among `own`'s and the others', and
/// writes the winners' rows into `arrays`, their depth into `depth_out` and 1 into
/// `mask_out`, which are own's full-frame arrays (own's hits are read at a pixel before
/// it is written).
template <class Depth>
void merge_frames(const Hits<Depth>& own, const std::vector<Frame<Depth>>& others, double tie,
                  const std::vector<Rows>& arrays, Depth* depth_out, uint8_t* mask_out) {
    if (others.empty()) return;
    std::vector<const uint8_t*> masks;
    for (const Frame<Depth>& f : others) masks.push_back(f.hits.hit);
    std::vector<int64_t> pixels;
    any_hit_pixels(masks, own.pixels, pixels);
    std::vector<std::vector<int64_t>> won(others.size());  // (each other's winning pixels)
    std::vector<double> depths;
    std::vector<std::size_t> from;
    const auto merge = [&](auto decide) {  // decide(p): the other whose hit wins at pixel p, or -1
        for (std::size_t k = 0; k < pixels.size(); ++k) {
            if (k + kRowsAhead < pixels.size()) {  // (the frames' rows at the pixels ahead: a cache miss each)
                const int64_t ahead = pixels[k + kRowsAhead];
                prefetch_line(own.hit + ahead);
                prefetch_line(own.depth + ahead);
                for (const Frame<Depth>& f : others) prefetch_line(f.hits.depth + ahead);
            }
            const int64_t p = pixels[k];
            const int s = decide(p);
            if (s < 0) continue;
            won[std::size_t(s)].push_back(p);
            depth_out[p] = others[std::size_t(s)].hits.depth[p];
            mask_out[p] = 1;
        }
    };
    if (others.size() == 1) {  // (two ranks on the node: two hits compared)
        const Hits<Depth>& o = others[0].hits;
        merge([&](int64_t p) {
            const bool mine = own.hit[p] != 0;
            return other_wins(
                       mine, mine ? double(own.depth[p]) : 0.0, double(o.depth[p]), tie, [&] { return own.key(p); },
                       [&] { return o.key(p); })
                       ? 0
                       : -1;
        });
    } else {
        merge([&](int64_t p) {
            depths.clear(), from.clear();
            for (std::size_t s = 0; s < others.size(); ++s)
                if (others[s].hits.hit[p]) depths.push_back(double(others[s].hits.depth[p])), from.push_back(s);
            const bool mine = own.hit[p] != 0;
            const int w = pick_winner(
                mine, mine ? double(own.depth[p]) : 0.0, depths.data(), depths.size(), tie, [&] { return own.key(p); },
                [&](std::size_t k) { return others[from[k]].hits.key(p); });
            return w < 0 ? -1 : int(from[std::size_t(w)]);
        });
    }
    for (std::size_t s = 0; s < others.size(); ++s) {
        const auto at = [&](std::size_t k) { return std::size_t(won[s][k]); };
        for (std::size_t a = 0; a < arrays.size(); ++a)
            copy_rows(arrays[a].width, others[s].rows[a].data, arrays[a].data, won[s].size(), at, at,
                      kFetchSource | kFetchTarget);
    }
}

}  // namespace vrc::compositing
