// Python bindings of the compositing passes (compositing.hpp), for vtkraycast/parallel.py:
// byte buffers in and out without copies, the GIL released around every pass.
#include <nanobind/nanobind.h>
#include <nanobind/ndarray.h>
#include <nanobind/stl/optional.h>
#include <nanobind/stl/vector.h>

#include <optional>
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
template <class T>
using Mutable = nb::ndarray<T, nb::ndim<1>, nb::c_contig, nb::device::cpu>;
using Out = Mutable<uint8_t>;
using Regions = nb::ndarray<const int64_t, nb::shape<-1, 4>, nb::c_contig, nb::device::cpu>;

nb::ndarray<nb::numpy, int64_t> int64s(std::vector<int64_t>&& values) {
    auto* held = new std::vector<int64_t>(std::move(values));
    nb::capsule owner(held, [](void* p) noexcept { delete static_cast<std::vector<int64_t>*>(p); });
    const std::size_t shape[1] = {held->size()};
    return nb::ndarray<nb::numpy, int64_t>(held->data(), 1, shape, owner);
}

std::vector<cmp::Rows> rows_of(const std::vector<Bytes>& arrays) {
    std::vector<cmp::Rows> rows;
    for (const Bytes& a : arrays) rows.push_back({a.data(), a.shape(0), a.shape(1)});
    return rows;
}

template <class Depth>
cmp::Hits<Depth> hits_of(const In<uint8_t>& hit, const In<int64_t>& triangle, const In<Depth>& depth,
                         const In<int64_t>& keys) {
    const std::size_t pixels = hit.shape(0);
    if (triangle.shape(0) != pixels || depth.shape(0) != pixels)
        throw std::invalid_argument("vtkValidPointMask, TriangleId and Depth differ in length");
    return {hit.data(), triangle.data(), depth.data(), pixels, keys.data(), keys.shape(0)};
}

template <class Depth>
nb::ndarray<nb::numpy, int64_t> send(In<uint8_t> hit, In<int64_t> triangle, In<Depth> depth, In<int64_t> keys,
                                     int64_t width, Regions regions, std::vector<Bytes> arrays, Out out) {
    const cmp::Hits<Depth> hits = hits_of(hit, triangle, depth, keys);
    if (width <= 0 || hits.pixels % std::size_t(width) != 0) throw std::invalid_argument("a frame of whole rows is needed");
    std::vector<cmp::Region> rs;
    for (std::size_t i = 0; i < regions.shape(0); ++i)
        rs.emplace_back(regions(i, 0), regions(i, 1), regions(i, 2), regions(i, 3), width);
    for (const cmp::Region& r : rs)
        if (r.first() < 0 || std::size_t(r.end()) > hits.pixels) throw std::invalid_argument("a region beyond the frame");
    const std::vector<cmp::Rows> rows = rows_of(arrays);
    for (const cmp::Rows& a : rows)
        if (a.rows != hits.pixels) throw std::invalid_argument("every array needs one row per pixel");
    std::vector<int64_t> bytes(rs.size());
    {
        nb::gil_scoped_release release;
        cmp::send_hits(hits, rs, rows, out.data(), out.shape(0), bytes.data());
    }
    return int64s(std::move(bytes));
}

template <class Depth>
void receive(In<uint8_t> messages, In<int64_t> bytes, std::optional<In<uint8_t>> hit,
             std::optional<In<int64_t>> triangle, std::optional<In<Depth>> depth, std::optional<In<int64_t>> keys,
             double tie, std::vector<Bytes> arrays, std::optional<Mutable<Depth>> depth_out,
             std::optional<Mutable<uint8_t>> mask_out, std::size_t pixels) {
    int64_t total = 0;
    for (std::size_t s = 0; s < bytes.shape(0); ++s) total += bytes.data()[s];
    if (total != int64_t(messages.shape(0))) throw std::invalid_argument("message sizes do not add up");
    std::optional<cmp::Hits<Depth>> own;
    if (hit) {
        if (!triangle || !depth || !keys) throw std::invalid_argument("own hits need their mask, triangles, depths and keys");
        own = hits_of(*hit, *triangle, *depth, *keys);
        if (own->pixels != pixels) throw std::invalid_argument("own hits cover the region, row for row");
    }
    const std::vector<cmp::Rows> rows = rows_of(arrays);
    for (const cmp::Rows& a : rows)
        if (a.rows != pixels) throw std::invalid_argument("every array needs one row per pixel of the region");
    if ((depth_out && depth_out->shape(0) != pixels) || (mask_out && mask_out->shape(0) != pixels))
        throw std::invalid_argument("Depth and vtkValidPointMask need one row per pixel of the region");
    nb::gil_scoped_release release;
    cmp::receive_hits(messages.data(), bytes.data(), bytes.shape(0), own ? &*own : nullptr, tie, rows,
                      depth_out ? depth_out->data() : nullptr, mask_out ? mask_out->data() : nullptr, pixels);
}

template <class Depth>
void merge(In<uint8_t> hit, In<int64_t> triangle, Mutable<Depth> depth, In<int64_t> keys, std::vector<In<uint8_t>> hits,
           std::vector<In<int64_t>> triangles, std::vector<In<Depth>> depths, std::vector<In<int64_t>> others_keys,
           std::vector<std::vector<Bytes>> others_arrays, double tie, std::vector<Bytes> arrays, Mutable<uint8_t> mask) {
    if (triangle.shape(0) != hit.shape(0) || depth.shape(0) != hit.shape(0))
        throw std::invalid_argument("vtkValidPointMask, TriangleId and Depth differ in length");
    const cmp::Hits<Depth> own{hit.data(), triangle.data(), depth.data(), hit.shape(0), keys.data(), keys.shape(0)};
    const std::size_t n = hits.size();
    if (triangles.size() != n || depths.size() != n || others_keys.size() != n || others_arrays.size() != n)
        throw std::invalid_argument("every other rank needs its mask, triangles, depths, keys and arrays");
    const std::vector<cmp::Rows> rows = rows_of(arrays);
    std::vector<cmp::Frame<Depth>> others;
    for (std::size_t s = 0; s < n; ++s) {
        others.push_back({hits_of(hits[s], triangles[s], depths[s], others_keys[s]), rows_of(others_arrays[s])});
        if (others.back().hits.pixels != own.pixels || others.back().rows.size() != rows.size())
            throw std::invalid_argument("the ranks' frames differ in size or arrays");
        for (std::size_t a = 0; a < rows.size(); ++a)
            if (others.back().rows[a].width != rows[a].width || others.back().rows[a].rows != own.pixels)
                throw std::invalid_argument("the ranks' frames differ in an array's rows");
    }
    for (const cmp::Rows& a : rows)
        if (a.rows != own.pixels) throw std::invalid_argument("every array needs one row per pixel");
    if (mask.data() != hit.data() || mask.shape(0) != own.pixels)
        throw std::invalid_argument("own vtkValidPointMask is written in place");
    nb::gil_scoped_release release;
    cmp::merge_frames(own, others, tie, rows, depth.data(), mask.data());
}

}  // namespace

void bind_compositing(nb::module_& m) {
    const char* send_doc =
        "Writes into `out`, for each receiving region (x0, x1, y0, y1), the records (place in the region, depth, "
        "global key of the hit triangle) and rows of this rank's hits in it, one message after the other; returns "
        "each message's size.";
    m.def("composite_send", &send<double>, "hit"_a, "triangle_id"_a, "depth"_a, "keys"_a, "width"_a, "regions"_a,
          "arrays"_a, "out"_a, send_doc);
    m.def("composite_send", &send<float>, "hit"_a, "triangle_id"_a, "depth"_a, "keys"_a, "width"_a, "regions"_a,
          "arrays"_a, "out"_a, send_doc);
    const char* receive_doc =
        "Keeps, per pixel of this rank's region, the received hit the serial cast keeps (least depth, then lowest "
        "key within the tie tolerance), against this rank's own hits when given (the region's rows of its "
        "full-frame arrays, which are then the region arrays): writes the winners' rows into `arrays`, their depth into `depth_out`, 1 into "
        "`mask_out`.";
    auto bind_receive = [&](auto f) {
        m.def("composite_receive", f, "messages"_a, "bytes"_a, "hit"_a.none(), "triangle_id"_a.none(),
              "depth"_a.none(), "keys"_a.none(), "tie"_a, "arrays"_a, "depth_out"_a.none(),
              "mask_out"_a.none(), "pixels"_a, receive_doc);
    };
    bind_receive(&receive<double>);
    bind_receive(&receive<float>);
    const char* merge_doc =
        "Composites into this rank's full-frame arrays (its hits' mask, triangles, depths and keys, and `arrays`, "
        "written in place) the other ranks' full-frame images (one list entry each, read in memory the ranks of a "
        "node share): per pixel, the hit the serial cast keeps (least depth, then lowest key within the tie "
        "tolerance).";
    auto bind_merge = [&](auto f) {
        m.def("composite_merge", f, "hit"_a, "triangle_id"_a, "depth"_a, "keys"_a, "hits"_a, "triangle_ids"_a,
              "depths"_a, "others_keys"_a, "others_arrays"_a, "tie"_a, "arrays"_a, "mask"_a, merge_doc);
    };
    bind_merge(&merge<double>);
    bind_merge(&merge<float>);
}
