// Python bindings of the compositing passes (compositing.hpp), for vtkraycast/parallel.py:
// byte buffers in and out without copies, the GIL released around every pass.
#include <nanobind/nanobind.h>
#include <nanobind/ndarray.h>
#include <nanobind/stl/vector.h>

#include <stdexcept>
#include <vector>

#include "compositing.hpp"

namespace nb = nanobind;
using namespace nb::literals;

namespace {

namespace cmp = vrc::compositing;

template <class T>
using In = nb::ndarray<const T, nb::ndim<1>, nb::c_contig, nb::device::cpu>;
using Bytes = nb::ndarray<uint8_t, nb::ndim<2>, nb::c_contig, nb::device::cpu>;
using Out = nb::ndarray<uint8_t, nb::ndim<1>, nb::c_contig, nb::device::cpu>;
using Regions = nb::ndarray<const int64_t, nb::shape<-1, 4>, nb::c_contig, nb::device::cpu>;

nb::ndarray<nb::numpy, int64_t> int64s(std::vector<int64_t>&& values) {
    auto* held = new std::vector<int64_t>(std::move(values));
    nb::capsule owner(held, [](void* p) noexcept { delete static_cast<std::vector<int64_t>*>(p); });
    const std::size_t shape[1] = {held->size()};
    return nb::ndarray<nb::numpy, int64_t>(held->data(), 1, shape, owner);
}

const cmp::HitRecord* records_of(const In<uint8_t>& bytes) {
    if (bytes.shape(0) % sizeof(cmp::HitRecord) != 0) throw std::invalid_argument("records of the wrong size");
    return reinterpret_cast<const cmp::HitRecord*>(bytes.data());
}

std::vector<int64_t> block_starts(const In<int64_t>& starts, std::size_t pixels) {
    std::vector<int64_t> s(starts.data(), starts.data() + starts.shape(0));
    if (s.size() < 2 || s.front() != 0 || std::size_t(s.back()) != pixels)
        throw std::invalid_argument("block starts must run from 0 to the number of pixels");
    for (std::size_t b = 1; b < s.size(); ++b)
        if (s[b] < s[b - 1] || s[b] - s[b - 1] > int64_t(UINT32_MAX))
            throw std::invalid_argument("blocks must be ascending and under 2**32 pixels");
    return s;
}

std::vector<cmp::Rows> rows_of(const std::vector<Bytes>& arrays) {
    std::vector<cmp::Rows> rows;
    for (const Bytes& a : arrays) rows.push_back({a.data(), a.shape(0), a.shape(1)});
    return rows;
}

template <class Depth>
nb::ndarray<nb::numpy, int64_t> records(In<uint8_t> hit, In<int64_t> triangle, In<Depth> depth, In<int64_t> keys,
                                        In<int64_t> starts, Out out) {
    const std::size_t pixels = hit.shape(0);
    if (triangle.shape(0) != pixels || depth.shape(0) != pixels)
        throw std::invalid_argument("vtkValidPointMask, TriangleId and Depth differ in length");
    if (out.shape(0) < pixels * sizeof(cmp::HitRecord)) throw std::invalid_argument("no room for a record per pixel");
    const std::vector<int64_t> s = block_starts(starts, pixels);
    std::vector<int64_t> counts(s.size() - 1);
    {
        nb::gil_scoped_release release;
        cmp::hit_records(hit.data(), triangle.data(), depth.data(), keys.data(), keys.shape(0), s.data(),
                         counts.size(), counts.data(), reinterpret_cast<cmp::HitRecord*>(out.data()));
    }
    return int64s(std::move(counts));
}

}  // namespace

void bind_compositing(nb::module_& m) {
    const char* records_doc =
        "Writes the hit pixels' records (offset in the deciding block, depth, global key of the hit triangle) into "
        "`out` (room for one per pixel), grouped by the blocks of `starts`; returns how many each block has.";
    m.def("composite_records", &records<double>, "hit"_a, "triangle_id"_a, "depth"_a, "keys"_a, "starts"_a, "out"_a,
          records_doc);
    m.def("composite_records", &records<float>, "hit"_a, "triangle_id"_a, "depth"_a, "keys"_a, "starts"_a, "out"_a,
          records_doc);
    m.def(
        "composite_resolve",
        [](In<uint8_t> records, std::size_t pixels, double tie, Out scratch, Out won) {
            const std::size_t n = records.shape(0) / sizeof(cmp::HitRecord);
            const cmp::HitRecord* r = records_of(records);
            if (scratch.shape(0) < pixels * sizeof(cmp::Best)) throw std::invalid_argument("no room for the block");
            if (won.shape(0) != n) throw std::invalid_argument("one flag per record is needed");
            for (std::size_t i = 0; i < n; ++i)
                if (r[i].offset >= pixels) throw std::invalid_argument("a record names a pixel outside the block");
            nb::gil_scoped_release release;
            cmp::resolve(r, n, tie, reinterpret_cast<cmp::Best*>(scratch.data()), won.data());
        },
        "records"_a, "pixels"_a, "tie"_a, "scratch"_a, "won"_a,
        "Flags (`won`, one byte per record of a block of `pixels` pixels) the records that win their pixel: least "
        "depth, then lowest key within the tie tolerance. `scratch`: 16 bytes per pixel of the block.");
    m.def(
        "composite_rows",
        [](In<uint8_t> records, In<int64_t> counts, In<int64_t> starts, In<uint8_t> won, int64_t width,
           Regions regions, std::vector<Bytes> arrays, Out out) {
            const cmp::HitRecord* r = records_of(records);
            if (won.shape(0) != records.shape(0) / sizeof(cmp::HitRecord))
                throw std::invalid_argument("one flag per record is needed");
            const std::vector<int64_t> s = block_starts(starts, std::size_t(starts.data()[starts.shape(0) - 1]));
            if (counts.shape(0) + 1 != s.size()) throw std::invalid_argument("one count per block is needed");
            int64_t total = 0;
            for (std::size_t b = 0; b < counts.shape(0); ++b) total += counts.data()[b];
            if (total * int64_t(sizeof(cmp::HitRecord)) != int64_t(records.shape(0)))
                throw std::invalid_argument("the counts do not add up to the records");
            std::vector<cmp::Region> rs;
            for (std::size_t i = 0; i < regions.shape(0); ++i)
                rs.emplace_back(regions(i, 0), regions(i, 1), regions(i, 2), regions(i, 3), width);
            const std::vector<cmp::Rows> rows = rows_of(arrays);
            for (const cmp::Rows& a : rows)
                if (a.rows != std::size_t(s.back())) throw std::invalid_argument("every array needs one row per pixel");
            std::vector<int64_t> bytes(rs.size());
            {
                nb::gil_scoped_release release;
                const cmp::WonPixels pixels(r, counts.data(), s.data(), counts.shape(0), won.data());
                cmp::winner_rows(pixels, rs, rows, out.data(), out.shape(0), bytes.data());
            }
            return int64s(std::move(bytes));
        },
        "records"_a, "counts"_a, "starts"_a, "won"_a, "width"_a, "regions"_a, "arrays"_a, "out"_a,
        "Writes into `out`, for each receiving region (x0, x1, y0, y1), the places and rows of the pixels this rank "
        "won in it, one message after the other; returns each message's size.");
    m.def(
        "composite_write",
        [](In<uint8_t> messages, In<int64_t> bytes, std::vector<Bytes> arrays) {
            int64_t total = 0;
            for (std::size_t s = 0; s < bytes.shape(0); ++s) total += bytes.data()[s];
            if (total != int64_t(messages.shape(0))) throw std::invalid_argument("message sizes do not add up");
            const std::vector<cmp::Rows> rows = rows_of(arrays);
            nb::gil_scoped_release release;
            cmp::write_rows(messages.data(), bytes.data(), bytes.shape(0), rows);
        },
        "messages"_a, "bytes"_a, "arrays"_a, "Writes received messages' rows into this rank's region arrays.");
}
